//! The furnished room the localizer's benchmarks run in: 10 × 8 m, walls
//! 10 cm thick, three boxes.

/// Whether a point of the room (metres) is solid; everything outside it is.
pub fn solid(x: f64, y: f64) -> bool {
    let outside = !(0.0..10.0).contains(&x) || !(0.0..8.0).contains(&y);
    let wall = !(0.1..=9.9).contains(&x) || !(0.1..=7.9).contains(&y);
    let boxes = [
        (2.0, 1.5, 3.2, 2.3),
        (6.0, 4.0, 6.5, 6.5),
        (6.5, 4.0, 8.0, 4.6),
    ];
    outside
        || wall
        || boxes
            .iter()
            .any(|&(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y))
}
