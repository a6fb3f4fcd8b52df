//! AFL target: [`geodex::fuzzing::png`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::png(data);
    });
}
