//! Which backends this build has, named in one place: [`Host`], the CPU backend that host-side
//! work runs on, and [`backend_list!`](crate::backend_list), the list of enabled backends that
//! the test, bench and dispatch macros are built on.
//!
//! # Why the list is decided here
//! A `#[cfg(feature = "tch")]` written inside a `macro_rules!` expansion is evaluated with the
//! features of the crate that *calls* the macro, not of phi-core, so a list spelled that way
//! would miss backends that phi-core has (or name ones it lacks) whenever the two disagree.
//! Instead, each backend has one step macro below, defined under phi-core's own feature: the
//! enabled version appends the backend's record to the list, the disabled one passes the list
//! on unchanged. The decision is taken when phi-core is compiled.
//!
//! Adding a backend means adding its record here, as one more step in the chain
//! `ndarray → burn → burn_wgpu → tch → end`.

#[cfg(feature = "ndarray")]
use super::ndarray::NdArray as HostBackend;

#[cfg(all(not(feature = "ndarray"), feature = "burn"))]
use super::burn::Burn as HostBackend;

#[cfg(all(not(feature = "ndarray"), not(feature = "burn"), feature = "tch"))]
use super::tch::Tch as HostBackend;

/// The CPU backend that code needing concrete host tensors uses (seeding particles, drawing
/// random scenes, generating datasets, rasterising obstacles to host masks): `NdArray` when the
/// `ndarray` feature is on (always, for phi-flip and the `phi` crate, which require it), else
/// `Burn` on its CPU backend, else `Tch` on the CPU. It does not exist in a build without any of
/// the three.
#[cfg(any(feature = "ndarray", feature = "burn", feature = "tch"))]
pub type Host = HostBackend;

/// Calls `callback!` with the list of backends compiled into phi-core, one record per backend:
///
/// ```text
/// callback! { (args...)
///     { ndarray, Ndarray, "ndarray", phi_core::backend::ndarray::NdArray, false, true, "doc" }
///     { burn, Burn, "burn", phi_core::backend::burn::Burn, true, true, "doc" }
///     ...
/// }
/// ```
///
/// A record is `{ module, Variant, "name", Type, autodiff, host, "doc" }`: a snake-case name
/// for a module of tests, a camel-case one for an enum variant, the name the command line and
/// [`Backend::name`](crate::Backend::name) use, the backend type, whether it implements
/// [`AutodiffBackend`](crate::AutodiffBackend) (`true` or `false`), whether its default device
/// is the host CPU, so that tests and benches run on it on every machine (`true` or `false`;
/// wgpu's is a GPU), and one line saying what it is. Records come in the order of preference:
/// ndarray, Burn, Burn on wgpu, tch.
///
/// Match the record fields with `$autodiff:tt` and `$host:tt` (not `literal`), so that another
/// macro can still match the `true` and `false` tokens. The callback is a path (`$crate::`
/// prefixes work) followed by `!` and its own arguments in parentheses, which come first.
///
/// ```
/// macro_rules! names {
///     (() $({ $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt,
///             $host:tt, $doc:literal })*) => {
///         [$($name),*]
///     };
/// }
/// let names: &[&str] = &phi_core::backend_list!(names!());
/// # #[cfg(feature = "ndarray")]
/// assert_eq!(names[0], "ndarray");
/// ```
#[macro_export]
macro_rules! backend_list {
    ($($callback:ident)::+ ! ($($args:tt)*)) => {
        $crate::__phi_backend_ndarray! { [($($args)*) $($callback)::+] [] }
    };
}

#[cfg(feature = "ndarray")]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_ndarray {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_burn! { [$($callback)*] [$($list)* {
            ndarray, Ndarray, "ndarray", $crate::backend::ndarray::NdArray, false, true,
            "ndarray + rayon: forward only, the fast CPU path."
        }] }
    };
}

#[cfg(not(feature = "ndarray"))]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_ndarray {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_burn! { [$($callback)*] [$($list)*] }
    };
}

#[cfg(feature = "burn")]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_burn {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_wgpu! { [$($callback)*] [$($list)* {
            burn, Burn, "burn", $crate::backend::burn::Burn, true, true,
            "Burn with autodiff on its CPU backend."
        }] }
    };
}

#[cfg(not(feature = "burn"))]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_burn {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_wgpu! { [$($callback)*] [$($list)*] }
    };
}

#[cfg(feature = "wgpu")]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_wgpu {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_tch! { [$($callback)*] [$($list)* {
            burn_wgpu, BurnWgpu, "burn-wgpu", $crate::backend::burn::BurnWgpu, true, false,
            "Burn with autodiff on a wgpu device (Vulkan, Metal, ...)."
        }] }
    };
}

#[cfg(not(feature = "wgpu"))]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_wgpu {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_tch! { [$($callback)*] [$($list)*] }
    };
}

#[cfg(feature = "tch")]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_tch {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_list_end! { [$($callback)*] [$($list)* {
            tch, Tch, "tch", $crate::backend::tch::Tch, true, true,
            "libtorch through tch, with its autograd."
        }] }
    };
}

#[cfg(not(feature = "tch"))]
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_tch {
    ([$($callback:tt)*] [$($list:tt)*]) => {
        $crate::__phi_backend_list_end! { [$($callback)*] [$($list)*] }
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_list_end {
    ([$args:tt $($callback:ident)::+] [$($list:tt)*]) => {
        $($callback)::+! { $args $($list)* }
    };
}

/// `then` or `otherwise`, chosen by a `true` or `false` token of a [`backend_list!`] record.
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_if {
    (true { $($then:tt)* } else { $($otherwise:tt)* }) => { $($then)* };
    (false { $($then:tt)* } else { $($otherwise:tt)* }) => { $($otherwise)* };
}

/// `tokens` if the backend of a record is in the selection: `all` takes every backend whose
/// default device is the host, `autodiff` those of them with gradients.
#[doc(hidden)]
#[macro_export]
macro_rules! __phi_if_selected {
    (all, $autodiff:tt, $host:tt { $($tokens:tt)* }) => {
        $crate::__phi_if! { $host { $($tokens)* } else {} }
    };
    (autodiff, $autodiff:tt, $host:tt { $($tokens:tt)* }) => {
        $crate::__phi_if! { $autodiff {
            $crate::__phi_if! { $host { $($tokens)* } else {} }
        } else {} }
    };
}

/// Writes one `#[test]` per enabled backend for each generic test function listed, in a module
/// per backend named by the record's module: `backend_tests!(unary_ops)` in module `forward`
/// gives `forward::ndarray::unary_ops`, `forward::burn::unary_ops`, `forward::tch::unary_ops`, each
/// calling `super::unary_ops::<B>()`. The functions' bounds are theirs to choose; the macro only
/// names each with each backend type.
///
/// Backends whose default device is not the host (wgpu) are left out, so that the tests run on
/// every machine.
///
/// ```
/// use phi_core::{Backend, Tensor};
///
/// fn zeros_sum_to_zero<B: Backend>() {
///     let zeros = Tensor::<B>::zeros(&[2, 3], &B::default_device());
///     assert_eq!(zeros.sum().to_vec(), vec![0.0]);
/// }
///
/// // `mod ndarray { #[test] fn zeros_sum_to_zero() { ... } }`, `mod burn { ... }`, ...
/// phi_core::backend_tests!(zeros_sum_to_zero);
/// # fn main() {}
/// ```
#[macro_export]
macro_rules! backend_tests {
    ($($test:ident),* $(,)?) => {
        $crate::backend_list!($crate::__phi_backend_tests!(all [$($test)*]));
    };
}

/// [`backend_tests!`] for the backends with autodiff: functions bounded by
/// [`AutodiffBackend`](crate::AutodiffBackend) (or a trait above it).
///
/// ```
/// use phi_core::{AutodiffBackend, Tensor};
///
/// fn gradient_of_a_sum_is_one<B: AutodiffBackend>() {
///     let x = Tensor::<B>::from_vec(vec![1.0, 2.0], &[2], &B::default_device()).unwrap();
///     let x = x.require_grad();
///     let gradients = x.sum().gradients(&[&x]).unwrap();
///     assert_eq!(gradients[0].to_vec(), vec![1.0, 1.0]);
/// }
///
/// phi_core::autodiff_backend_tests!(gradient_of_a_sum_is_one);
/// # fn main() {}
/// ```
#[macro_export]
macro_rules! autodiff_backend_tests {
    ($($test:ident),* $(,)?) => {
        $crate::backend_list!($crate::__phi_backend_tests!(autodiff [$($test)*]));
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_tests {
    (($selection:ident $tests:tt) $({
        $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt, $host:tt,
        $doc:literal
    })*) => {
        $($crate::__phi_if_selected! { $selection, $autodiff, $host {
            $crate::__phi_backend_test_module! { $module, $backend, $tests }
        } })*
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __phi_backend_test_module {
    ($module:ident, $backend:ty, [$($test:ident)*]) => {
        mod $module {
            $(#[test] fn $test() { super::$test::<$backend>(); })*
        }
    };
}

/// Runs `body` once per enabled backend with the type alias `B` bound to it, in list order
/// (ndarray, Burn, tch): a bench or a comparison across backends written once.
///
/// Backends whose default device is not the host (wgpu) are left out, as in
/// [`backend_tests!`].
///
/// ```
/// use phi_core::Backend;
///
/// let mut names: Vec<&str> = Vec::new();
/// phi_core::for_each_backend!(B => names.push(B::name()));
/// # #[cfg(feature = "ndarray")]
/// assert_eq!(names[0], "ndarray");
/// ```
#[macro_export]
macro_rules! for_each_backend {
    ($B:ident => $body:expr) => {
        $crate::backend_list!($crate::__phi_for_each_backend!(all $B $body))
    };
}

/// [`for_each_backend!`] for the backends with autodiff.
///
/// ```
/// use phi_core::Backend;
///
/// let mut names: Vec<&str> = Vec::new();
/// phi_core::for_each_autodiff_backend!(B => names.push(B::name()));
/// assert!(!names.contains(&"ndarray"));
/// ```
#[macro_export]
macro_rules! for_each_autodiff_backend {
    ($B:ident => $body:expr) => {
        $crate::backend_list!($crate::__phi_for_each_backend!(autodiff $B $body))
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __phi_for_each_backend {
    (($selection:ident $B:ident $body:expr) $({
        $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt, $host:tt,
        $doc:literal
    })*) => {{
        $($crate::__phi_if_selected! { $selection, $autodiff, $host {{
            type $B = $backend;
            $body;
        }} })*
    }};
}

// Without any backend the lists are empty and the functions below would have no caller.
#[cfg(all(test, any(feature = "ndarray", feature = "burn", feature = "tch")))]
mod tests {
    use crate::{Backend, Tensor};

    /// The command-line names of the records, each with the name its backend reports and the
    /// record's flags.
    macro_rules! records {
        (() $({
            $module:ident, $variant:ident, $name:literal, $backend:ty, $autodiff:tt, $host:tt,
            $doc:literal
        })*) => {
            vec![$(($name, <$backend as Backend>::name(), $autodiff, $host)),*]
        };
    }

    type Record = (&'static str, &'static str, bool, bool);

    #[test]
    fn the_list_follows_the_features_of_phi_core() {
        let records: Vec<Record> = crate::backend_list!(records!());
        let mut expected = Vec::new();
        if cfg!(feature = "ndarray") {
            expected.push(("ndarray", false, true));
        }
        if cfg!(feature = "burn") {
            expected.push(("burn", true, true));
        }
        if cfg!(feature = "wgpu") {
            expected.push(("burn-wgpu", true, false));
        }
        if cfg!(feature = "tch") {
            expected.push(("tch", true, true));
        }
        let got: Vec<(&str, bool, bool)> = records
            .iter()
            .map(|&(name, _, autodiff, host)| (name, autodiff, host))
            .collect();
        assert_eq!(got, expected);
        for (name, reported, _, _) in records {
            assert_eq!(name, reported, "the record's name and Backend::name");
        }
    }

    #[test]
    fn for_each_backend_visits_the_host_backends_in_order() {
        let mut names = Vec::new();
        crate::for_each_backend!(B => names.push(B::name()));
        let records: Vec<Record> = crate::backend_list!(records!());
        let hosts: Vec<&str> = records.iter().filter(|r| r.3).map(|r| r.0).collect();
        assert_eq!(names, hosts);
    }

    #[cfg(any(feature = "burn", feature = "tch"))]
    #[test]
    fn for_each_autodiff_backend_visits_the_host_backends_with_gradients() {
        use crate::AutodiffBackend;

        fn gradient_of_a_sum<B: AutodiffBackend>() -> Vec<f32> {
            let x = Tensor::<B>::from_vec(vec![1.0, 2.0], &[2], &B::default_device())
                .unwrap()
                .require_grad();
            x.sum().gradients(&[&x]).unwrap()[0].to_vec()
        }
        let mut got = Vec::new();
        crate::for_each_autodiff_backend!(B => got.push((B::name(), gradient_of_a_sum::<B>())));
        let records: Vec<Record> = crate::backend_list!(records!());
        let expected: Vec<(&str, Vec<f32>)> = records
            .iter()
            .filter(|r| r.2 && r.3)
            .map(|r| (r.0, vec![1.0, 1.0]))
            .collect();
        assert_eq!(got, expected);
    }

    /// Runs as `tests::<backend>::creates_tensors_on_its_default_device`, one per host backend.
    fn creates_tensors_on_its_default_device<B: Backend>() {
        let device = B::default_device();
        let t = Tensor::<B>::from_vec(vec![1.0, 2.0, 3.0], &[3], &device).unwrap();
        assert_eq!(t.sum().to_vec(), vec![6.0], "{}", B::name());
    }

    crate::backend_tests!(creates_tensors_on_its_default_device);

    /// The autodiff tests sit in their own module: both macros name a backend's module after it.
    #[cfg(any(feature = "burn", feature = "tch"))]
    mod autodiff {
        use crate::{AutodiffBackend, Tensor};

        /// Runs as `tests::autodiff::<backend>::tracks_gradients`, one per host backend with
        /// autodiff.
        fn tracks_gradients<B: AutodiffBackend>() {
            let x = Tensor::<B>::from_vec(vec![3.0], &[1], &B::default_device())
                .unwrap()
                .require_grad();
            assert!(x.is_tracked(), "{}", B::name());
        }

        crate::autodiff_backend_tests!(tracks_gradients);
    }
}
