//! AFL target: [`geodex::fuzzing::json_bodies`].
fn main() {
    afl::fuzz!(|data: &[u8]| {
        geodex::fuzzing::json_bodies(data);
    });
}
