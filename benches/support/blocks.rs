//! The blocks of flat-roofed buildings the generated benchmark grids carry (`benches/render.rs`,
//! `benches/big_database.rs`): in every 200 m square, a chequer of 20 m blocks in its middle
//! 80 m, built in a third of the squares.

/// The roof height (metres) of the building on 1 m cell `(c, r)` over ground at `ground`
/// metres, if one stands there: 8 to 40 m above it, the same rise for every cell of a square.
pub fn roof(c: usize, r: usize, ground: f32) -> Option<f32> {
    let (bx, by) = (c % 200, r % 200);
    let h = ((c / 200) * 7919 + (r / 200) * 104_729) % 97;
    let building = bx > 60
        && bx < 140
        && by > 60
        && by < 140
        && (bx / 20 + by / 20) % 2 == 0
        && h.is_multiple_of(3);
    building.then_some(ground + 8.0 + (h % 33) as f32)
}
