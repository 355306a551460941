//! Choosing a backend at run time: the names the command line accepts, and
//! [`with_backend!`](crate::with_backend), which runs code generic over
//! [`Backend`](phi_core::Backend) on the chosen one.
//!
//! Both are the run-time form of phi-core's list of enabled backends
//! ([`phi_core::backend_list!`]), which the tests and benches use too: this module names no
//! backend itself, so a backend added to that list reaches the command line unchanged.

use std::fmt;

/// Defines [`BackendKind`] from the records of [`phi_core::backend_list!`].
macro_rules! backend_kind {
    (() $({
        $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt, $host:tt,
        $doc:literal
    })*) => {
        /// A backend compiled into this build, by its command-line name.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum BackendKind {
            $(#[doc = $doc] $variant,)*
        }

        impl BackendKind {
            /// Every backend compiled into this build, the default first.
            pub fn available() -> Vec<BackendKind> {
                vec![$(BackendKind::$variant),*]
            }

            /// The name the command line uses.
            pub fn name(self) -> &'static str {
                match self {
                    $(BackendKind::$variant => $name,)*
                }
            }

            /// Whether the backend computes gradients.
            pub fn has_autodiff(self) -> bool {
                match self {
                    $(BackendKind::$variant => $autodiff,)*
                }
            }
        }
    };
}

phi_core::backend_list!(backend_kind!());

/// The default backends, one rule for every command (stated in `phi --help` and the README).
impl BackendKind {
    /// The default of the commands that run without gradients (`simulate`, `rollout`, `eval`):
    /// the first backend compiled in, ndarray (every build has it: phi-flip requires it).
    pub fn default_forward() -> BackendKind {
        BackendKind::available()[0]
    }

    /// The default of the commands that need gradients (`train`, `optimize`): the first backend
    /// compiled in that has autodiff, burn in the default build; `None` in a build without one.
    pub fn default_autodiff() -> Option<BackendKind> {
        BackendKind::available()
            .into_iter()
            .find(|kind| kind.has_autodiff())
    }

    /// What to pass instead of a backend without autodiff, for the refusals of `train` and
    /// `optimize`: `--backend burn, burn-wgpu or tch` with the autodiff backends of this build.
    pub(crate) fn autodiff_hint() -> String {
        let names: Vec<&str> = BackendKind::available()
            .into_iter()
            .filter(|kind| kind.has_autodiff())
            .map(BackendKind::name)
            .collect();
        match names.as_slice() {
            [] => "this build has no backend with autodiff".to_string(),
            [one] => format!("use --backend {one}"),
            [rest @ .., last] => format!("use --backend {} or {last}", rest.join(", ")),
        }
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
        $crate::phi_core::backend_list!($crate::__with_backend_arms!($kind, $B, $body))
    };
}

/// Like [`with_backend!`](crate::with_backend), for backends with autodiff; `$otherwise` runs
/// for the others.
#[macro_export]
macro_rules! with_autodiff_backend {
    ($kind:expr, $B:ident => $body:expr, otherwise => $otherwise:expr) => {
        $crate::phi_core::backend_list!($crate::__with_autodiff_backend_arms!(
            $kind, $B, $body, $otherwise
        ))
    };
}

/// The `match` of [`with_backend!`](crate::with_backend): one arm per record of
/// [`phi_core::backend_list!`].
#[doc(hidden)]
#[macro_export]
macro_rules! __with_backend_arms {
    (($kind:expr, $B:ident, $body:expr) $({
        $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt, $host:tt,
        $doc:literal
    })*) => {
        match $kind {
            $($crate::backends::BackendKind::$variant => {
                type $B = $backend;
                $body
            })*
        }
    };
}

/// The `match` of [`with_autodiff_backend!`](crate::with_autodiff_backend): `$body` for the
/// records with autodiff, `$otherwise` for the others.
#[doc(hidden)]
#[macro_export]
macro_rules! __with_autodiff_backend_arms {
    (($kind:expr, $B:ident, $body:expr, $otherwise:expr) $({
        $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt, $host:tt,
        $doc:literal
    })*) => {
        match $kind {
            $($crate::backends::BackendKind::$variant => $crate::phi_core::__phi_if! { $autodiff {{
                type $B = $backend;
                $body
            }} else { $otherwise } },)*
        }
    };
}

#[cfg(test)]
mod tests {
    use phi_core::Backend;

    use super::BackendKind;

    #[test]
    fn every_kind_dispatches_to_the_backend_of_its_name() {
        let kinds = BackendKind::available();
        assert_eq!(kinds[0].name(), "ndarray", "the default comes first");
        assert_eq!(BackendKind::default_forward(), kinds[0]);
        let autodiff_default = BackendKind::default_autodiff().unwrap();
        assert!(autodiff_default.has_autodiff());
        assert!(
            kinds
                .iter()
                .take_while(|k| **k != autodiff_default)
                .all(|k| !k.has_autodiff()),
            "{autodiff_default} is not the first with autodiff"
        );
        if cfg!(feature = "burn") {
            assert_eq!(autodiff_default.name(), "burn");
        }
        for kind in kinds {
            assert_eq!(crate::with_backend!(kind, B => B::name()), kind.name());
            let autodiff =
                crate::with_autodiff_backend!(kind, B => Some(B::name()), otherwise => None);
            assert_eq!(autodiff.is_some(), kind.has_autodiff(), "{kind}");
            assert_eq!(kind.name().parse::<BackendKind>().unwrap(), kind);
        }
        // The refusal of a backend without autodiff names exactly this build's autodiff ones.
        let hint = BackendKind::autodiff_hint();
        for kind in BackendKind::available() {
            assert_eq!(
                hint.contains(&format!(" {}", kind.name())),
                kind.has_autodiff(),
                "{kind}: {hint}"
            );
        }
        let unknown = "numpy".parse::<BackendKind>().unwrap_err().to_string();
        assert!(
            unknown.contains("`numpy`") && unknown.contains("ndarray"),
            "{unknown}"
        );
    }
}
