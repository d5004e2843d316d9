//! Building one tile's expected-range table (64 × 64 cells of 5 cm, 120
//! headings, 360 rays) in a 10 × 8 m room with walls and three boxes: rays
//! shared along lines (`fill_table`, what the localizer builds) beside each
//! cell's own rays (`fill_table_ray_by_ray`, the build before), in the
//! same run.

#![allow(missing_docs)] // criterion_group! generates an undocumented function.

use criterion::{Criterion, criterion_group, criterion_main};
use deog_grid::{CellBox, CellIndex, Resolution};
use deog_localizer::range_table::{
    ConeGeometry, OccupancyRaster, fill_table, fill_table_ray_by_ray,
};
use std::hint::black_box;

#[path = "common/room.rs"]
mod room;
use room::solid;

fn tables(c: &mut Criterion) {
    let res = Resolution::DEFAULT;
    let geometry = ConeGeometry::default();
    let tile = CellBox::new(CellIndex::new(64, 64), CellIndex::new(127, 127)).unwrap();
    let m = geometry.margin_cells(res);
    let bounds = CellBox::new(
        CellIndex::new(tile.min.x - m, tile.min.y - m),
        CellIndex::new(tile.max.x + m, tile.max.y + m),
    )
    .unwrap();
    let raster = OccupancyRaster::new(bounds, |cell| {
        let (x, y) = res.cell_center(cell);
        (-0.5..10.5).contains(&x) && (-0.5..8.5).contains(&y) && solid(x, y)
    });
    let mut table = vec![0u16; tile.width() as usize * tile.height() as usize * geometry.stride()];
    let mut group = c.benchmark_group("range_table");
    group.sample_size(10);
    group.bench_function("shared_lines/64x64", |b| {
        b.iter(|| fill_table(&raster, tile, res, &geometry, black_box(&mut table)))
    });
    group.bench_function("ray_by_ray/64x64", |b| {
        b.iter(|| fill_table_ray_by_ray(&raster, tile, res, &geometry, black_box(&mut table)))
    });
    group.finish();
}

criterion_group!(benches, tables);
criterion_main!(benches);
