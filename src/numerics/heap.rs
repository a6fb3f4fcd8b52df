//! Indexed binary min-heap with decrease-key: the narrow band of fast marching.
