//! AFL target: [`geodex::fuzzing::npy`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::npy(data);
    });
}
