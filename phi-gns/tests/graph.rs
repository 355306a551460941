//! Integration tests of `phi_gns::graph`, the radius graph, with modules by topic.

#[path = "graph/batch.rs"]
mod batch;
#[path = "graph/brute_force.rs"]
mod brute_force;
#[path = "graph/common.rs"]
mod common;
#[path = "graph/edge_cases.rs"]
mod edge_cases;
#[path = "graph/errors.rs"]
mod errors;
