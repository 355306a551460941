//! Integration tests of phi: one binary, modules by topic.

#[cfg(feature = "ndarray")]
mod cli;
#[cfg(feature = "ndarray")]
mod conformance;
#[cfg(feature = "ndarray")]
mod fields;
mod parsers;
#[cfg(feature = "ndarray")]
mod solve;
