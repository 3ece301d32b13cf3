//! Lit specks in a weak shadow: ground texture, not sunlight.
//!
//! Under a low sun (or a bright sky) a shadow keeps 75–90 % of the lit ground's shadow index —
//! a weak split ([`crate::shadow::detect::WEAK_DARK_RATIO`]) — and the ground's own texture
//! varies about as much, so the brightest patches of shaded grass read lit. A scan line ends
//! at the first lit cell: in the POV-Ray town at 12° the lines of a 17 m roof ended 8–9 m out
//! on a 7-cell patch of shaded grass (index 90–95, threshold 88.5, lit grass ~97) and the roof
//! came back 14 m low. Sunlight that reaches the ground past the town's casters comes through
//! gaps between them and lies in wedges metres long along the sun; a patch of a few square
//! metres wholly ringed by shadow is the texture.
//!
//! Invariant: only a *weak* split is touched (the window's shadow class's mean index at least
//! [`crate::shadow::detect::MAX_DARK_RATIO`] × its lit class's; a clear split's shadow is far
//! darker than any texture); only a lit component (8-connected) smaller than
//! [`MAX_SPECK_M2`] whose every neighbour is [`Class::Shadow`] or [`Class::Unusable`] (ground
//! in a neighbour's shadow, second pass) becomes shadow — one touching a footprint, an edge
//! cell or the window's border keeps its class (what lies beyond is unknown). Nothing else
//! changes.

use super::local::Class;
use crate::shadow::detect::MAX_DARK_RATIO;

/// A lit patch ringed by shadow smaller than this (square metres) is texture in a weak
/// shadow: the POV-Ray town's shaded grass reads lit in patches of up to ~4 m² (16 cells of
/// 0.5 m) at 12°.
pub const MAX_SPECK_M2: f64 = 4.0;

/// Whether the window's split is weak: the mean ground bin (`ground`, the shadow index
/// rounded) of its [`Class::Shadow`] cells is at least [`MAX_DARK_RATIO`] × that of its
/// [`Class::Lit`] cells. `false` when either class is empty.
pub fn weak_split(class: &[Class], ground: &[u16]) -> bool {
    let (mut dark, mut lit) = ((0.0, 0usize), (0.0, 0usize));
    for (c, &g) in class.iter().zip(ground) {
        match c {
            Class::Shadow => dark = (dark.0 + g as f64, dark.1 + 1),
            Class::Lit => lit = (lit.0 + g as f64, lit.1 + 1),
            _ => {}
        }
    }
    dark.1 > 0 && lit.1 > 0 && dark.0 / dark.1 as f64 >= MAX_DARK_RATIO * lit.0 / lit.1 as f64
}

/// Turn to [`Class::Shadow`] every lit speck of `class` (row-major, `width` cells a row): a
/// [`Class::Lit`] component (8-connected) of fewer than `max_cells` cells whose every
/// 8-neighbour is [`Class::Shadow`] or [`Class::Unusable`] and which stays off the window's
/// border (the module's
/// invariant). The caller decides the split is weak ([`weak_split`]). Returns the cells changed.
pub fn fill_lit_specks(class: &mut [Class], width: usize, max_cells: usize) -> usize {
    let height = class.len() / width.max(1);
    let mut seen = vec![false; class.len()];
    let mut changed = 0;
    let mut stack = Vec::new();
    let mut component = Vec::new();
    for start in 0..class.len() {
        if seen[start] || class[start] != Class::Lit {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        component.clear();
        let mut ringed = true;
        while let Some(i) = stack.pop() {
            component.push(i);
            let (c, r) = (i % width, i / width);
            if c == 0 || r == 0 || c + 1 == width || r + 1 == height {
                ringed = false;
            }
            for rr in r.saturating_sub(1)..=(r + 1).min(height - 1) {
                for cc in c.saturating_sub(1)..=(c + 1).min(width - 1) {
                    let j = rr * width + cc;
                    match class[j] {
                        Class::Lit if !seen[j] => {
                            seen[j] = true;
                            stack.push(j);
                        }
                        // Unusable open ground: in a neighbour's shadow (second pass) or the bare
                        // terrain's, or nodata (the photo's edge: ends the ring below).
                        Class::Lit | Class::Shadow | Class::Unusable => {}
                        _ => ringed = false,
                    }
                }
            }
        }
        if ringed && component.len() < max_cells {
            for &i in &component {
                class[i] = Class::Shadow;
            }
            changed += component.len();
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w` × `h` window of shadow with `lit` cells (column, row) lit.
    fn window(w: usize, h: usize, lit: &[(usize, usize)]) -> Vec<Class> {
        let mut class = vec![Class::Shadow; w * h];
        for &(c, r) in lit {
            class[r * w + c] = Class::Lit;
        }
        class
    }

    #[test]
    fn a_small_lit_patch_ringed_by_shadow_becomes_shadow() {
        let mut class = window(10, 10, &[(4, 4), (5, 4), (4, 5), (5, 5), (6, 6)]);
        assert_eq!(fill_lit_specks(&mut class, 10, 16), 5);
        assert!(class.iter().all(|&c| c == Class::Shadow));
    }

    #[test]
    fn large_patches_border_patches_and_patches_against_footprints_stay_lit() {
        // 16 cells: not smaller than 16.
        let big: Vec<(usize, usize)> = (2..6).flat_map(|r| (2..6).map(move |c| (c, r))).collect();
        let mut class = window(10, 10, &big);
        assert_eq!(fill_lit_specks(&mut class, 10, 16), 0);
        // On the window's border: what lies beyond is unknown.
        let mut class = window(10, 10, &[(0, 4), (1, 4)]);
        assert_eq!(fill_lit_specks(&mut class, 10, 16), 0);
        // Against another footprint (its sunlit roof may cover part of it).
        let mut class = window(10, 10, &[(4, 4), (5, 4)]);
        class[3 * 10 + 6] = Class::Other;
        assert_eq!(fill_lit_specks(&mut class, 10, 16), 0);
        assert_eq!(class[4 * 10 + 4], Class::Lit);
    }

    #[test]
    fn only_a_shadow_close_to_the_lit_ground_is_weak() {
        let class = [Class::Shadow, Class::Lit, Class::Own];
        // Shadow 80 against lit grass 97 (the town at 12°, sRGB): 0.82, weak.
        assert!(weak_split(&class, &[80, 97, 200]));
        // Shadow 45 against 97: a clear split.
        assert!(!weak_split(&class, &[45, 97, 200]));
        assert!(!weak_split(&[Class::Lit, Class::Own], &[97, 200]));
    }
}
