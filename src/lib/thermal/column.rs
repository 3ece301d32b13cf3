//! A surface's temperature profile stepped through time by backward Euler, with the surface
//! energy balance as the top boundary.
//!
//! Each step solves, for every unknown node i with capacity C_i and conductances K to its
//! neighbours,
//!   C_i·(T_i' − T_i)/Δt = K_{i−1}·(T_{i−1}' − T_i') + K_i·(T_{i+1}' − T_i')
//! at the new time (primes), and at the surface node adds the balance
//!   F(T₀') = (1 − albedo)·S + ε·L↓ − ε·σ·T₀'⁴ − h·(T₀' − T_air) − LE(T₀'),
//! where an evaporating surface (surface resistance r_s) loses the latent heat
//!   LE(T) = (e_s(T) − e_air)/γ · h / (1 + h·r_s/(ρ·c_p))
//! (the Penman–Monteith form of FAO-56, Allen et al. 1998, eqs. 3 and 8, with the aerodynamic
//! resistance r_a = ρ·c_p/h of the same convective exchange: γ = 67.4 Pa/K at 101.3 kPa,
//! ρ·c_p = 1206 J/(m³·K)); e_s is convex and increasing like T⁴ and is linearised with it.
//! The tridiagonal system is eliminated from the bottom up (Thomas), which leaves every node
//! as T_i' = p_i + q_i·T_{i−1}' and the surface as one scalar equation in T₀'; the only
//! nonlinear term, T⁴, is linearised about the current iterate and Newton-iterated until an
//! update is below the tolerance; then the profile follows by back substitution.
//!
//! Invariants: the scheme is unconditionally stable (every row is diagonally dominant, so
//! 0 ≤ q_i < 1 and no step size amplifies an error); a step allocates nothing; and the
//! [`Budget`] closes to round-off: its emitted term is the linearised emission the converged
//! solve used, which differs from ε·σ·T₀'⁴ by less than 6·ε·σ·T³·tolerance².

use super::forcing::{saturation_vapour_pressure_pa, Forcing, STEFAN_BOLTZMANN};
use super::grid::{Grid, GridSpec};
use super::surface::Surface;
use crate::{Error, Result};

/// The most Newton iterations a step may take; the scalar surface equation is convex and
/// increasing, so Newton converges monotonically after its first iterate and needs a handful.
const MAX_NEWTON: usize = 50;

/// The psychrometric constant γ at sea-level pressure 101.3 kPa, Pa/K (FAO-56, eq. 8:
/// γ = 0.665·10⁻³·P).
const PSYCHROMETRIC_PA_PER_K: f64 = 0.665e-3 * 101_300.0;
/// Volumetric heat capacity of air ρ·c_p, J/(m³·K) (1.2 kg/m³ × 1005 J/(kg·K)).
const AIR_HEAT_CAPACITY_J_PER_M3_K: f64 = 1206.0;

/// Energy through a column's boundaries since it was made or [`Column::reset_budget`], J/m²,
/// each positive in the direction its name says.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Budget {
    /// (1 − albedo)·S·Δt summed: shortwave absorbed.
    pub shortwave_absorbed_j_per_m2: f64,
    /// ε·L↓·Δt summed: sky long-wave absorbed.
    pub longwave_absorbed_j_per_m2: f64,
    /// ε·σ·T₀⁴·Δt summed (as linearised by the converged Newton step): emitted.
    pub emitted_j_per_m2: f64,
    /// h·(T₀ − T_air)·Δt summed: given to the air.
    pub convected_j_per_m2: f64,
    /// LE·Δt summed (as linearised by the converged Newton step): latent heat evaporated
    /// (negative: dew).
    pub evaporated_j_per_m2: f64,
    /// A prescribed surface flux (the flux-only boundary) summed: put in.
    pub prescribed_j_per_m2: f64,
    /// Through the bottom boundary, into the column.
    pub bottom_in_j_per_m2: f64,
    /// Σ C_i·ΔT_i: the change in stored heat.
    pub stored_j_per_m2: f64,
}

impl Budget {
    /// What came in through the boundaries minus what was stored, J/m²: 0 up to round-off.
    pub fn residual_j_per_m2(&self) -> f64 {
        self.shortwave_absorbed_j_per_m2 + self.longwave_absorbed_j_per_m2
            - self.emitted_j_per_m2
            - self.convected_j_per_m2
            - self.evaporated_j_per_m2
            + self.prescribed_j_per_m2
            + self.bottom_in_j_per_m2
            - self.stored_j_per_m2
    }

    /// The sum of every term's magnitude, J/m²: the scale to judge the residual against.
    pub fn magnitude_j_per_m2(&self) -> f64 {
        [
            self.shortwave_absorbed_j_per_m2,
            self.longwave_absorbed_j_per_m2,
            self.emitted_j_per_m2,
            self.convected_j_per_m2,
            self.evaporated_j_per_m2,
            self.prescribed_j_per_m2,
            self.bottom_in_j_per_m2,
            self.stored_j_per_m2,
        ]
        .iter()
        .map(|v| v.abs())
        .sum()
    }
}

/// The result of [`Column::run_periodic`].
#[derive(Debug, Clone, PartialEq)]
pub struct Periodic {
    /// Surface temperature, K, at the end of each step of the last cycle.
    pub surface_k: Vec<f64>,
    /// How many cycles were run.
    pub cycles: usize,
    /// The largest change of the surface temperature at the same time of day between the last
    /// two cycles, K (infinite after a single cycle).
    pub change_k: f64,
}

/// A surface's temperature profile and what it takes to step it.
#[derive(Debug, Clone)]
pub struct Column {
    albedo: f64,
    emissivity: f64,
    /// r_s, s/m, of an evaporating surface.
    surface_resistance: Option<f64>,
    grid: Grid,
    /// Node temperatures, K, surface first.
    temperature: Vec<f64>,
    /// Elimination coefficients (one more than the nodes: the bottom's p = T_bottom, q = 0).
    p: Vec<f64>,
    q: Vec<f64>,
    newton_tolerance_k: f64,
    budget: Budget,
    /// Σ C_i·T_i when the budget was last reset, J/m².
    heat_at_reset: f64,
}

/// The surface boundary of one step: F(T) = absorbed + prescribed − εσ·T⁴ − h·(T − T_air).
struct Top {
    shortwave: f64,
    longwave: f64,
    prescribed: f64,
    eps_sigma: f64,
    h: f64,
    air_k: f64,
    /// An evaporating surface's LE(T) = coefficient·(e_s(T) − e_air): (W/(m²·Pa), Pa).
    evaporation: Option<(f64, f64)>,
}

impl Column {
    /// A column for a surface, gridded by `spec`, with temperature `initial_k(depth_m)` at each
    /// node; Newton stops when an update of the surface temperature is below
    /// `newton_tolerance_k`, K (> 0; 1e-6 is plenty: the budget then closes to round-off).
    pub fn new(
        surface: &Surface,
        spec: GridSpec,
        newton_tolerance_k: f64,
        initial_k: impl Fn(f64) -> f64,
    ) -> Result<Column> {
        surface.validate()?;
        if !(newton_tolerance_k > 0.0 && newton_tolerance_k.is_finite()) {
            return Err(Error::msg(format!(
                "Newton tolerance {newton_tolerance_k} K is not positive"
            ))
            .fix("give a tolerance such as 1e-6 K"));
        }
        let grid = Grid::new(surface, spec)?;
        let temperature: Vec<f64> = grid.depth.iter().map(|&z| initial_k(z)).collect();
        if let Some(t) = temperature.iter().find(|t| !(**t > 0.0 && t.is_finite())) {
            return Err(
                Error::msg(format!("initial temperature {t} K is not above 0 K"))
                    .fix("give the initial profile in kelvin"),
            );
        }
        let n = temperature.len();
        let mut column = Column {
            albedo: surface.albedo,
            emissivity: surface.emissivity,
            surface_resistance: surface.surface_resistance_s_per_m,
            grid,
            temperature,
            p: vec![0.0; n + 1],
            q: vec![0.0; n + 1],
            newton_tolerance_k,
            budget: Budget::default(),
            heat_at_reset: 0.0,
        };
        column.reset_budget();
        Ok(column)
    }

    /// Depth of each node, m, surface first (the held bottom node of a ground is not one).
    pub fn depths_m(&self) -> &[f64] {
        &self.grid.depth
    }

    /// Temperature of each node, K, surface first.
    pub fn temperatures_k(&self) -> &[f64] {
        &self.temperature
    }

    /// The surface temperature, K.
    pub fn surface_k(&self) -> f64 {
        self.temperature[0]
    }

    /// The energy budget since the column was made or last reset.
    pub fn budget(&self) -> Budget {
        Budget {
            stored_j_per_m2: self.heat() - self.heat_at_reset,
            ..self.budget
        }
    }

    /// Starts the budget afresh from the current profile.
    pub fn reset_budget(&mut self) {
        self.budget = Budget::default();
        self.heat_at_reset = self.heat();
    }

    /// Σ C_i·T_i, J/m².
    fn heat(&self) -> f64 {
        self.grid
            .capacity
            .iter()
            .zip(&self.temperature)
            .map(|(c, t)| c * t)
            .sum()
    }

    /// One step of `dt_s` seconds (> 0) under `forcing`; returns the new surface temperature, K.
    /// Give the forcing at the step's end, where backward Euler balances it: forcing from the
    /// step's middle lags the response by half a step (on a summer day with 10-minute steps,
    /// 0.43 K instead of 0.09 K from a fine run; `docs/thermal.md`).
    pub fn step(&mut self, forcing: &Forcing, dt_s: f64) -> Result<f64> {
        forcing.validate()?;
        let top = self.top(forcing);
        self.step_with(&top, dt_s)
    }

    /// The surface boundary under `forcing`.
    fn top(&self, forcing: &Forcing) -> Top {
        Top {
            shortwave: (1.0 - self.albedo) * forcing.shortwave_w_per_m2,
            longwave: self.emissivity * forcing.longwave_down_w_per_m2,
            prescribed: 0.0,
            eps_sigma: self.emissivity * STEFAN_BOLTZMANN,
            h: forcing.convection_w_per_m2_k,
            air_k: forcing.air_temperature_k,
            evaporation: self.surface_resistance.map(|r_s| {
                let h = forcing.convection_w_per_m2_k;
                let coefficient =
                    h / (1.0 + h * r_s / AIR_HEAT_CAPACITY_J_PER_M3_K) / PSYCHROMETRIC_PA_PER_K;
                (coefficient, forcing.vapour_pressure_pa)
            }),
        }
    }

    /// Sets the profile to the steady state under constant `forcing` (backward Euler with an
    /// infinite step) and restarts the budget; returns the surface temperature, K. Settled
    /// under a day's mean forcing, a column starts its periodic run near its daily mean: the
    /// road of `docs/thermal.md` then needs 15 cycles to 1e-4 K instead of 28 from a uniform
    /// 290 K.
    pub fn settle(&mut self, forcing: &Forcing) -> Result<f64> {
        forcing.validate()?;
        let top = self.top(forcing);
        let (surface, ..) = self.solve(&top, 0.0)?;
        self.reset_budget();
        Ok(surface)
    }

    /// One step of `dt_s` seconds with the flux-only boundary: `flux_w_per_m2` (either sign)
    /// enters the surface and nothing else crosses it (no radiation, no convection). For
    /// analytic checks and for callers that compute the surface balance themselves.
    pub fn step_flux(&mut self, flux_w_per_m2: f64, dt_s: f64) -> Result<f64> {
        if !flux_w_per_m2.is_finite() {
            return Err(
                Error::msg(format!("surface flux {flux_w_per_m2} W/m² is not a number"))
                    .fix("give a finite flux"),
            );
        }
        self.step_with(
            &Top {
                shortwave: 0.0,
                longwave: 0.0,
                prescribed: flux_w_per_m2,
                eps_sigma: 0.0,
                h: 0.0,
                air_k: 0.0,
                evaporation: None,
            },
            dt_s,
        )
    }

    /// Steps through `forcing`, one element per step of `dt_s` seconds; returns the surface
    /// temperature, K, at the end of each step.
    pub fn run(&mut self, forcing: &[Forcing], dt_s: f64) -> Result<Vec<f64>> {
        forcing.iter().map(|f| self.step(f, dt_s)).collect()
    }

    /// Repeats one day's `day` forcing (steps of `dt_s` seconds) from the current profile until
    /// the surface temperature at every time of day changes by less than `tolerance_k`, K,
    /// between two cycles, or `max_cycles` cycles have run: the preceding diurnal cycles of a
    /// surface whose history is not known. The result says how far it got; the column is left
    /// at the end of the last cycle.
    pub fn run_periodic(
        &mut self,
        day: &[Forcing],
        dt_s: f64,
        tolerance_k: f64,
        max_cycles: usize,
    ) -> Result<Periodic> {
        if day.is_empty() || max_cycles == 0 || !(tolerance_k > 0.0 && tolerance_k.is_finite()) {
            return Err(Error::msg(format!(
                "a periodic run of {} steps, {max_cycles} cycles, tolerance {tolerance_k} K",
                day.len()
            ))
            .fix("give at least one step, one cycle and a positive tolerance"));
        }
        let mut last = vec![f64::NAN; day.len()];
        let mut change_k = f64::INFINITY;
        let mut cycles = 0;
        while cycles < max_cycles && change_k >= tolerance_k {
            change_k = 0.0;
            for (f, prev) in day.iter().zip(last.iter_mut()) {
                let t = self.step(f, dt_s)?;
                change_k = f64::max(change_k, (t - *prev).abs());
                *prev = t;
            }
            if cycles == 0 {
                change_k = f64::INFINITY;
            }
            cycles += 1;
        }
        Ok(Periodic {
            surface_k: last,
            cycles,
            change_k,
        })
    }

    /// The backward-Euler step with the surface boundary `top`, booked in the budget.
    fn step_with(&mut self, top: &Top, dt_s: f64) -> Result<f64> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(Error::msg(format!("time step {dt_s} s is not positive"))
                .fix("give the step in seconds, such as 600"));
        }
        let (surface, emitted, evaporated) = self.solve(top, 1.0 / dt_s)?;
        let g = &self.grid;
        let n = self.temperature.len();
        let b = &mut self.budget;
        b.shortwave_absorbed_j_per_m2 += top.shortwave * dt_s;
        b.longwave_absorbed_j_per_m2 += top.longwave * dt_s;
        b.prescribed_j_per_m2 += top.prescribed * dt_s;
        b.emitted_j_per_m2 += emitted * dt_s;
        b.convected_j_per_m2 += top.h * (surface - top.air_k) * dt_s;
        b.evaporated_j_per_m2 += evaporated * dt_s;
        b.bottom_in_j_per_m2 +=
            g.conductance[n - 1] * (g.bottom_k - self.temperature[n - 1]) * dt_s;
        Ok(surface)
    }

    /// Solves the implicit system for the new profile with `inv_dt` = 1/Δt (0: the steady
    /// state); returns the surface temperature and the emission and latent heat the converged
    /// solve used, W/m².
    fn solve(&mut self, top: &Top, inv_dt: f64) -> Result<(f64, f64, f64)> {
        let g = &self.grid;
        let n = self.temperature.len();
        let (t, p, q) = (&mut self.temperature, &mut self.p, &mut self.q);
        // Eliminate from the bottom: T_i' = p_i + q_i·T_{i−1}'.
        p[n] = g.bottom_k;
        q[n] = 0.0;
        for i in (1..n).rev() {
            let (above, below) = (g.conductance[i - 1], g.conductance[i]);
            let c = g.capacity[i] * inv_dt;
            let den = c + above + below * (1.0 - q[i + 1]);
            p[i] = (c * t[i] + below * p[i + 1]) / den;
            q[i] = above / den;
        }
        // The surface: α·T + εσ·T⁴ + h·T = β, with the node below as p₁ + q₁·T.
        let k0 = g.conductance[0];
        let c0 = g.capacity[0] * inv_dt;
        let alpha = c0 + k0 * (1.0 - q[1]) + top.h;
        let beta = c0 * t[0]
            + k0 * p[1]
            + top.shortwave
            + top.longwave
            + top.prescribed
            + top.h * top.air_k;
        let mut around = t[0];
        let mut surface = t[0];
        let mut evaporated = 0.0;
        for iteration in 0.. {
            // Emission linearised about `around`: εσ·(a⁴ + 4a³·(T − a)); latent heat likewise:
            // L(a) + L'(a)·(T − a).
            let a3 = top.eps_sigma * around * around * around;
            let (l, dl) = top.evaporation.map_or((0.0, 0.0), |(k, e_air)| {
                let (e_s, de_s) = saturation_vapour_pressure_pa(around);
                (k * (e_s - e_air), k * de_s)
            });
            surface = (beta + 3.0 * a3 * around - l + dl * around) / (alpha + 4.0 * a3 + dl);
            evaporated = l + dl * (surface - around);
            if (surface - around).abs() <= self.newton_tolerance_k {
                break;
            }
            if iteration == MAX_NEWTON || !surface.is_finite() {
                return Err(Error::msg(format!(
                    "the surface balance did not converge (last update {} K)",
                    surface - around
                ))
                .fix("check the forcing and the surface's values"));
            }
            around = surface;
        }
        let emitted = beta - alpha * surface - evaporated;
        t[0] = surface;
        for i in 1..n {
            t[i] = p[i] + q[i] * t[i - 1];
        }
        Ok((surface, emitted, evaporated))
    }
}
