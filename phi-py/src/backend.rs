//! The backends a call can run on, by the names the command line uses.

use crate::error::{Area, Error};

/// The backends of this build, the default first.
pub fn available() -> Vec<&'static str> {
    let mut names = vec!["ndarray"];
    if cfg!(feature = "burn") {
        names.push("burn");
    }
    names
}

/// The refusal of a backend name this build does not have.
pub fn unknown(name: &str) -> Error {
    Error::argument(
        Area::General,
        "backend",
        format!(
            "'{name}' is not a backend of this build (it has {})",
            available().join(", ")
        ),
    )
}

/// Runs `$body` with the type alias `$b` set to the backend named `$name`, or returns the
/// error of an unknown name.
macro_rules! with_backend {
    ($name:expr, $b:ident => $body:expr) => {{
        match $name {
            "ndarray" => {
                type $b = phi_core::backend::ndarray::NdArray;
                $body
            }
            #[cfg(feature = "burn")]
            "burn" => {
                type $b = phi_core::backend::burn::Burn;
                $body
            }
            other => Err($crate::backend::unknown(other)),
        }
    }};
}
pub(crate) use with_backend;
