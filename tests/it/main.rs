//! Integration tests of glissade: in-process LATIN runs against monolithic solutions and
//! analytic references, and the `glissade` binary end to end. One test binary.

mod acceleration;
mod allocations;
mod analytic;
mod axisymmetric;
mod bad_input;
mod bench;
mod bus_auth;
mod common;
mod distributed;
mod foreign;
mod full_disk;
mod fuzz_nodes;
mod generate;
mod gmsh;
mod latin_perfect;
mod layout;
mod monolithic;
mod node_failures;
mod non_matching;
mod pgd;
mod reactions;
mod real_router;
mod recording;
mod recovery;
mod reference;
mod reference_failure;
mod replay;
mod resultants;
mod run_id;
mod shared_router;
mod slurm;
mod stability;
mod stall;
mod statuses;
mod studies;
mod time_start;
mod tls;
mod two_hosts;
mod validate;
mod verified_outputs;
mod vtu;

#[global_allocator]
static ALLOCATOR: allocations::Counting = allocations::Counting;
