//! The Moon for night scenes (issue 18): where an observer sees it, how much of it is lit, and
//! how much light it and the moonless sky give the ground.
//!
//! [`moon_position`] gives the topocentric elevation and azimuth of the Moon's centre, its
//! distance, phase angle and illuminated fraction for an observer on the Earth at a UTC instant:
//! Meeus, *Astronomical Algorithms* (2nd ed., 1998), ch. 47 (truncated ELP-2000/82), with the
//! nutation, sidereal time, ΔT and refraction of the sun's NREL SPA (`crate::sun`), Meeus ch. 40
//! parallax and ch. 48 phase. [`moonlight`] and [`night_sky_lux`] turn that into lux.
//!
//! Invariants and conventions (the sun module's):
//! * azimuth is degrees clockwise from geographic north, always in [0, 360);
//! * elevation is degrees above the horizon in [−90, 90], topocentric (the Moon's parallax, up to
//!   1.02°, is in), and includes atmospheric refraction unless [`MoonOptions::refraction`] is off
//!   (SPA's formula and its continuous fade below the horizon, the same options as the sun);
//! * [`MoonPosition::direction_enu`] points from the ground TO the Moon, x east, y north, z up;
//! * the phase is geocentric (Meeus's and PyEphem's convention); the fraction is in [0, 1].

mod elp;
mod light;
mod phase;
mod sky;
mod terms;

pub use crate::sun::{Observer, SunOptions as MoonOptions};
pub use light::{
    moonlight, night_sky_lux, Moonlight, DEFAULT_EXTINCTION_MAG_PER_AIRMASS, MEAN_DISTANCE_KM,
};

use crate::sun::{spa, spa_input};
use crate::Result;
use chrono::{DateTime, Utc};

/// Kilometres in one astronomical unit (IAU 2012).
const AU_KM: f64 = 149_597_870.7;

/// The Moon as an observer sees it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MoonPosition {
    /// Degrees of the Moon's centre above the horizon, [−90, 90] (negative: below), topocentric.
    pub elevation_deg: f64,
    /// Degrees clockwise from true north, [0, 360).
    pub azimuth_deg: f64,
    /// Distance from the observer to the Moon's centre, km: 356 000..407 000 from the Earth's
    /// centre, ± one Earth radius (6378 km) from the observer.
    pub distance_km: f64,
    /// Sun–Moon–Earth angle, degrees, [0, 180]: 0 at full moon, 180 at new moon (geocentric).
    pub phase_angle_deg: f64,
    /// Fraction of the Moon's disc that is lit, (1 + cos phase angle) / 2, in [0, 1].
    pub illuminated_fraction: f64,
}

impl MoonPosition {
    /// Unit vector from the ground TO the Moon in the local east-north-up frame:
    /// `[cos e sin a, cos e cos a, sin e]` for elevation e, azimuth a.
    pub fn direction_enu(&self) -> [f64; 3] {
        let (e, a) = (
            self.elevation_deg.to_radians(),
            self.azimuth_deg.to_radians(),
        );
        [e.cos() * a.sin(), e.cos() * a.cos(), e.sin()]
    }

    /// The Moon's direct light on the ground from here ([`moonlight`]), through air of V-band
    /// extinction `extinction_mag_per_airmass` ([`DEFAULT_EXTINCTION_MAG_PER_AIRMASS`] for a clear
    /// night).
    pub fn light(&self, extinction_mag_per_airmass: f64) -> Result<Moonlight> {
        moonlight(
            self.elevation_deg,
            self.phase_angle_deg,
            self.distance_km,
            extinction_mag_per_airmass,
        )
    }
}

/// Topocentric position and phase of the Moon for `obs` at the UTC instant `utc`.
///
/// `opts` are the sun's ([`MoonOptions`] = [`crate::sun::SunOptions`]): refraction and its
/// atmosphere, ΔT (default: the Espenak & Meeus model, [`crate::sun::delta_t_model_s`]) and ΔUT1.
/// Meeus's series is for dates near the present: checked to 0.01° over 1950–2050; it degrades
/// slowly away from 2000 (the polynomials in T). Errors (one line, with the fix) when an input is
/// out of range or not a number, with the sun's ranges (years −2000..6000).
pub fn moon_position(
    obs: &Observer,
    utc: DateTime<Utc>,
    opts: &MoonOptions,
) -> Result<MoonPosition> {
    let input = spa_input(obs, utc, opts)?;
    // The sun gives the nutation, true obliquity, apparent sidereal time and its own place.
    let sun = spa::spa(&input);
    let t = (input.days_j2000 + input.delta_t_s / 86400.0) / 36525.0;
    let g = elp::geocentric(t);
    let moon = sky::apparent_equatorial(
        (g.lambda_deg + sun.delta_psi).to_radians(),
        g.beta_deg.to_radians(),
        sun.epsilon.to_radians(),
        g.distance_km,
    );
    let sun_eq = sky::Equatorial {
        alpha: sun.alpha.to_radians(),
        delta: sun.delta.to_radians(),
        distance_km: sun.r * AU_KM,
    };
    let (phase_angle, fraction) = phase::phase(&moon, &sun_eq);

    let phi = input.latitude_deg.to_radians();
    let hour_angle = (sun.nu + input.longitude_deg).to_radians() - moon.alpha;
    let (rho_sin, rho_cos) = sky::observer_rho(phi, input.height_m);
    let (h, delta, distance_km) =
        sky::topocentric(hour_angle, moon.delta, moon.distance_km, rho_sin, rho_cos);
    let (e0, azimuth) = sky::horizon(h, delta, phi);
    let e0 = e0.to_degrees();
    let refraction = input
        .refraction
        .map_or(0.0, |(p, t)| spa::refraction_deg(e0, p, t));
    Ok(MoonPosition {
        elevation_deg: (e0 + refraction).clamp(-90.0, 90.0),
        azimuth_deg: spa::wrap_deg(azimuth.to_degrees()),
        distance_km,
        phase_angle_deg: phase_angle.to_degrees(),
        illuminated_fraction: fraction,
    })
}

#[cfg(test)]
mod tests;
