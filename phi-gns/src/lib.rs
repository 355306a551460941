//! Graph Network-based Simulators trained on FLIP datasets.
