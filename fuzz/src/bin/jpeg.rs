//! AFL target: [`geodex::fuzzing::jpeg`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::jpeg(data);
    });
}
