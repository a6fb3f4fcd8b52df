//! AFL target: [`geodex::fuzzing::nifti`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::nifti(data);
    });
}
