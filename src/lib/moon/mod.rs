//! The moon: topocentric position, phase and the light it gives (issue 18). Filled in by the
//! submodules as they land.
