//! Surface temperature from a one-dimensional transient heat balance, and band radiance
//! (issue 18). Filled in by the submodules as they land.
