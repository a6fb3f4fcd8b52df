//! AFL target: [`geodex::fuzzing::tiff`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::tiff(data);
    });
}
