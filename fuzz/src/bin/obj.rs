//! AFL target: [`geodex::fuzzing::obj`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::obj(data);
    });
}
