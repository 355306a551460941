//! Choosing a backend at run time: the names the command line accepts, and [`with_backend!`],
//! which runs code generic over [`Backend`](phi_core::Backend) on the chosen one.

use std::fmt;

/// A backend compiled into this build, by its command-line name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BackendKind {
    /// ndarray + rayon: forward only, the fast CPU path.
    #[cfg(feature = "ndarray")]
    Ndarray,
    /// Burn with autodiff on its CPU backend.
    #[cfg(feature = "burn")]
    Burn,
    /// Burn with autodiff on a wgpu device (Vulkan, Metal, ...).
    #[cfg(feature = "wgpu")]
    BurnWgpu,
    /// libtorch through tch, with its autograd.
    #[cfg(feature = "tch")]
    Tch,
}

impl BackendKind {
    /// Every backend compiled into this build, the default first.
    pub fn available() -> Vec<BackendKind> {
        vec![
            #[cfg(feature = "ndarray")]
            BackendKind::Ndarray,
            #[cfg(feature = "burn")]
            BackendKind::Burn,
            #[cfg(feature = "wgpu")]
            BackendKind::BurnWgpu,
            #[cfg(feature = "tch")]
            BackendKind::Tch,
        ]
    }

    /// The name the command line uses.
    pub fn name(self) -> &'static str {
        match self {
            #[cfg(feature = "ndarray")]
            BackendKind::Ndarray => "ndarray",
            #[cfg(feature = "burn")]
            BackendKind::Burn => "burn",
            #[cfg(feature = "wgpu")]
            BackendKind::BurnWgpu => "burn-wgpu",
            #[cfg(feature = "tch")]
            BackendKind::Tch => "tch",
        }
    }

    /// Whether the backend computes gradients.
    pub fn has_autodiff(self) -> bool {
        self.name() != "ndarray"
    }
}

impl fmt::Display for BackendKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Error for a backend name that is unknown or not compiled in.
#[derive(Debug, thiserror::Error)]
#[error("unknown backend `{name}`; this build has: {available}")]
pub struct UnknownBackend {
    name: String,
    available: String,
}

impl std::str::FromStr for BackendKind {
    type Err = UnknownBackend;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        BackendKind::available()
            .into_iter()
            .find(|kind| kind.name() == name)
            .ok_or_else(|| UnknownBackend {
                name: name.to_owned(),
                available: BackendKind::available()
                    .iter()
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }
}

/// Runs `$body` with the type alias `$B` bound to the backend `$kind` names.
///
/// ```text
/// with_backend!(kind, B => run::<B>(&args))
/// ```
#[macro_export]
macro_rules! with_backend {
    ($kind:expr, $B:ident => $body:expr) => {
        match $kind {
            #[cfg(feature = "ndarray")]
            $crate::backends::BackendKind::Ndarray => {
                type $B = $crate::phi_core::backend::ndarray::NdArray;
                $body
            }
            #[cfg(feature = "burn")]
            $crate::backends::BackendKind::Burn => {
                type $B = $crate::phi_core::backend::burn::Burn;
                $body
            }
            #[cfg(feature = "wgpu")]
            $crate::backends::BackendKind::BurnWgpu => {
                type $B = $crate::phi_core::backend::burn::BurnWgpu;
                $body
            }
            #[cfg(feature = "tch")]
            $crate::backends::BackendKind::Tch => {
                type $B = $crate::phi_core::backend::tch::Tch;
                $body
            }
        }
    };
}

/// Like [`with_backend!`], for backends with autodiff; `$otherwise` runs for the others.
#[macro_export]
macro_rules! with_autodiff_backend {
    ($kind:expr, $B:ident => $body:expr, otherwise => $otherwise:expr) => {
        match $kind {
            #[cfg(feature = "burn")]
            $crate::backends::BackendKind::Burn => {
                type $B = $crate::phi_core::backend::burn::Burn;
                $body
            }
            #[cfg(feature = "wgpu")]
            $crate::backends::BackendKind::BurnWgpu => {
                type $B = $crate::phi_core::backend::burn::BurnWgpu;
                $body
            }
            #[cfg(feature = "tch")]
            $crate::backends::BackendKind::Tch => {
                type $B = $crate::phi_core::backend::tch::Tch;
                $body
            }
            #[allow(unreachable_patterns)]
            _ => $otherwise,
        }
    };
}
