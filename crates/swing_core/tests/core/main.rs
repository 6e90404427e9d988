//! Integration tests of `swing_core` through its public API, one module per domain.
//!
//! One test binary rather than one per file: each binary links the whole core with thin LTO,
//! so a single binary builds in a fraction of the time nine did.

mod adaptive;
mod config;
mod control;
mod counting;
mod fixtures;
mod formats;
mod hostile;
mod layers;
mod mission;
mod plant;
mod sensors;
mod sysid;

#[global_allocator]
static ALLOC: counting::Counter = counting::Counter;
