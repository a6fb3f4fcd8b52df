//! AFL target: [`geodex::fuzzing::off`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::off(data);
    });
}
