//! Surface temperature from a one-dimensional transient heat balance, and band radiance
//! (issue 18, thermal infrared).
//!
//! A [`Surface`] (albedo, emissivity, a column of [`Layer`]s over a [`Bottom`]) becomes a
//! [`Column`] on a finite-volume [`GridSpec`] grid; each step of [`Forcing`] (shortwave on the
//! surface's plane, sky long-wave, air temperature, convection coefficient) is solved by
//! backward Euler with the surface energy balance Newton-iterated at the top. [`planck`] turns
//! the temperature into band radiance. The equations, the tests that pin them against
//! analytic truth and the cost of accuracy are in `docs/thermal.md`.
//!
//! Invariants: SI units throughout (K, m, s, W/m², J/m²); every value a user gives is
//! validated into an [`crate::Error`], never a panic; stepping is unconditionally stable,
//! allocation-free, and conserves energy to round-off ([`Budget`]).

mod column;
mod forcing;
mod grid;
pub mod planck;
mod surface;

#[cfg(test)]
mod analytic_tests;
#[cfg(test)]
mod feature_tests;

pub use column::{Budget, Column, Periodic};
pub use forcing::{
    brutsaert_clear_sky_longwave, mcadams_convection, saturation_vapour_pressure_pa, Forcing,
    STEFAN_BOLTZMANN,
};
pub use grid::GridSpec;
pub use surface::{Bottom, Layer, Surface};
