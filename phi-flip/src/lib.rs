//! The FLIP liquid simulator (thesis algorithm 1), written once against `phi_core::backend::Backend`.
