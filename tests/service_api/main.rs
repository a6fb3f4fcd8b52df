//! Integration tests of the HTTP service: each test starts the real server on
//! a free port (with its own data directory) and talks HTTP to it.

mod common;
mod connections;
mod conventions;
mod correspond;
mod datasets;
mod errors;
mod flow;
mod gradient;
mod group;
mod inverse;
mod level_set;
mod load;
mod memory;
mod mesh;
mod openapi;
mod paths;
mod pictures;
mod playground;
mod segment;
mod shape;

mod tensor;
mod tensor_metric_ops;
