//! AFL target: [`geodex::fuzzing::ply`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::ply(data);
    });
}
