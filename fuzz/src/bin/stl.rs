//! AFL target: [`geodex::fuzzing::stl`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::stl(data);
    });
}
