//! The 1-D finite-volume grid through a surface's layers.
//!
//! Nodes sit at depths z₀ = 0 (the surface) < z₁ < … < z_N (the bottom of the last layer), with
//! a node on every layer interface, so each element [z_j, z_{j+1}] lies inside one layer and its
//! conductance k/Δz is exact. A node's heat capacity is ρ·c times half of each element touching
//! it (an interface node takes half from each layer). Two neighbouring nodes exchange
//! K_j·(T_j − T_{j+1}); the conductance between two nodes on either side of an interface is the
//! series (harmonic-mean) one, which is what putting the node on the interface gives.
//!
//! Element thickness starts at `first_m` at the surface and grows geometrically by `growth`
//! with depth (Δz(z) = first + (growth − 1)·z); inside each layer the elements are scaled down
//! together so that they end exactly on the layer's bottom.
//!
//! Invariant: the depths strictly increase from 0 to the column's total thickness, every
//! capacity and conductance is positive and finite.

use super::surface::{Bottom, Surface};
use crate::{Error, Result};

/// How finely to resolve the column: the knobs that trade accuracy for time (see
/// `docs/thermal.md` for the table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    /// Thickness of the first element under the surface, m (> 0).
    pub first_m: f64,
    /// Ratio of each element's thickness to the one above it, ≥ 1 (1 is uniform).
    pub growth: f64,
}

impl Default for GridSpec {
    /// 5 mm at the surface, growing by 20 % per element (21 nodes in 1 m): 0.024 K of
    /// amplitude error on a diurnal half-space swinging 8.3 K (`docs/thermal.md`).
    fn default() -> GridSpec {
        GridSpec {
            first_m: 0.005,
            growth: 1.2,
        }
    }
}

/// The most nodes a column may have: a grid finer than this is a mistake, not a wish.
const MAX_NODES: usize = 100_000;

/// The discretised column: unknown nodes, their capacities and the conductances between them.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Grid {
    /// Depth of each unknown node, m, surface first.
    pub depth: Vec<f64>,
    /// Heat capacity of each unknown node's control volume, J/(m²·K).
    pub capacity: Vec<f64>,
    /// `conductance[i]`, W/(m²·K): between unknown node i and i + 1; the last one is to the
    /// bottom boundary (the fixed node under a ground, the interior under a roof).
    pub conductance: Vec<f64>,
    /// The temperature across the last conductance, K.
    pub bottom_k: f64,
}

impl Grid {
    /// The grid of a validated surface.
    pub fn new(surface: &Surface, spec: GridSpec) -> Result<Grid> {
        if !(spec.first_m > 0.0 && spec.first_m.is_finite()) {
            return Err(Error::msg(format!(
                "first element thickness {} m is not positive",
                spec.first_m
            ))
            .fix("give a thickness such as 0.005 m"));
        }
        if !(spec.growth >= 1.0 && spec.growth.is_finite()) {
            return Err(
                Error::msg(format!("element growth {} is below 1", spec.growth))
                    .fix("give a growth factor ≥ 1, such as 1.2"),
            );
        }
        let mut depth = vec![0.0];
        let mut capacity = vec![0.0];
        let mut conductance = Vec::new();
        let mut top = 0.0;
        for layer in &surface.layers {
            let elements = layer_elements(
                layer.thickness_m,
                spec.first_m + (spec.growth - 1.0) * top,
                spec.growth,
            );
            if depth.len() + elements.len() > MAX_NODES {
                return Err(
                    Error::msg(format!("the grid needs more than {MAX_NODES} nodes"))
                        .fix("give a thicker first element or a larger growth"),
                );
            }
            let rho_c = layer.heat_capacity_j_per_m3_k();
            let bottom = top + layer.thickness_m;
            let mut z = top;
            for (j, dz) in elements.iter().enumerate() {
                // The layer's last node lands exactly on its bottom, not on a rounded sum.
                let next = if j + 1 == elements.len() {
                    bottom
                } else {
                    z + dz
                };
                let dz = next - z;
                *capacity.last_mut().expect("starts with the surface node") += 0.5 * rho_c * dz;
                capacity.push(0.5 * rho_c * dz);
                conductance.push(layer.conductivity_w_per_m_k / dz);
                depth.push(next);
                z = next;
            }
            top = bottom;
        }
        let bottom_k = match surface.bottom {
            // The last node is the held one: not an unknown, its conductance leads to it.
            Bottom::Fixed { temperature_k } => {
                depth.pop();
                capacity.pop();
                temperature_k
            }
            Bottom::Convective {
                coefficient_w_per_m2_k,
                temperature_k,
            } => {
                conductance.push(coefficient_w_per_m2_k);
                temperature_k
            }
        };
        Ok(Grid {
            depth,
            capacity,
            conductance,
            bottom_k,
        })
    }
}

/// The element thicknesses of one layer: geometric from `first` by `growth`, as few as reach
/// `thickness`, then all scaled by the same factor (≤ 1) to sum to it.
fn layer_elements(thickness: f64, first: f64, growth: f64) -> Vec<f64> {
    let first = first.min(thickness);
    let n = if growth == 1.0 {
        (thickness / first).ceil()
    } else {
        ((1.0 + thickness * (growth - 1.0) / first).ln() / growth.ln()).ceil()
    };
    let n = (n as usize).clamp(1, MAX_NODES);
    let mut elements: Vec<f64> = (0..n).map(|j| first * growth.powi(j as i32)).collect();
    let scale = thickness / elements.iter().sum::<f64>();
    elements.iter_mut().for_each(|e| *e *= scale);
    elements
}

#[cfg(test)]
mod tests {
    use super::super::surface::Layer;
    use super::*;

    fn layer(thickness_m: f64, k: f64) -> Layer {
        Layer {
            thickness_m,
            conductivity_w_per_m_k: k,
            density_kg_per_m3: 1000.0,
            specific_heat_j_per_kg_k: 1000.0,
        }
    }

    fn roof() -> Surface {
        Surface {
            albedo: 0.1,
            emissivity: 0.9,
            surface_resistance_s_per_m: None,
            layers: vec![layer(0.01, 0.2), layer(0.1, 0.04), layer(0.2, 1.5)],
            bottom: Bottom::Convective {
                coefficient_w_per_m2_k: 8.0,
                temperature_k: 293.0,
            },
        }
    }

    /// Nodes land on every interface, the capacities add up to the column's ρ·c·thickness and
    /// the series resistance of the conductances is Σ thickness/k (mutation check: dropping
    /// the "lands exactly on its bottom" line moves an interface node by round-off and the
    /// interface test fails; giving an interface node one side's capacity fails the sum).
    #[test]
    fn nodes_honour_interfaces_and_conserve_capacity_and_resistance() {
        let s = roof();
        let g = Grid::new(&s, GridSpec::default()).unwrap();
        for z in [0.0, 0.01, 0.11, 0.31] {
            assert!(g.depth.contains(&z), "no node at {z}: {:?}", g.depth);
        }
        let total_c: f64 = g.capacity.iter().sum();
        assert!((total_c - 0.31e6).abs() < 1e-6, "{total_c}");
        let n = g.conductance.len();
        let r: f64 = g.conductance[..n - 1].iter().map(|k| 1.0 / k).sum();
        let want = 0.01 / 0.2 + 0.1 / 0.04 + 0.2 / 1.5;
        assert!((r - want).abs() < 1e-12, "{r} {want}");
        assert_eq!(g.conductance[n - 1], 8.0);
        assert_eq!(g.depth.len(), g.capacity.len());
        assert_eq!(g.depth.len(), g.conductance.len());
        assert!(g.depth.windows(2).all(|w| w[1] > w[0]));
    }

    /// Under a fixed bottom the held node is not an unknown; the elements grow by the factor.
    #[test]
    fn a_fixed_bottom_is_not_an_unknown_and_elements_grow() {
        let s = Surface {
            layers: vec![layer(1.0, 1.0)],
            bottom: Bottom::Fixed {
                temperature_k: 280.0,
            },
            ..roof()
        };
        let g = Grid::new(
            &s,
            GridSpec {
                first_m: 0.01,
                growth: 1.1,
            },
        )
        .unwrap();
        assert_eq!(g.bottom_k, 280.0);
        assert!(*g.depth.last().unwrap() < 1.0);
        let dz: Vec<f64> = g.depth.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            dz.windows(2).all(|w| (w[1] / w[0] - 1.1).abs() < 1e-9),
            "{dz:?}"
        );
        assert!(dz[0] <= 0.01);
        assert!(Grid::new(
            &s,
            GridSpec {
                first_m: 0.0,
                growth: 1.1
            }
        )
        .is_err());
        assert!(Grid::new(
            &s,
            GridSpec {
                first_m: 0.01,
                growth: 0.9
            }
        )
        .is_err());
        assert!(Grid::new(
            &s,
            GridSpec {
                first_m: 1e-9,
                growth: 1.0
            }
        )
        .is_err());
    }
}
