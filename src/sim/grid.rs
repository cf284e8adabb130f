//! Uniform grid for neighbour search on the ground plane.
//!
//! Rebuilt every frame from the previous frame's positions with a counting
//! sort, so agents inside one cell stay in index order and a query visits
//! neighbours in a fixed order whatever the thread count: sums over
//! neighbours are bit-identical run to run.

use glam::Vec2;

/// Most cells a grid may allocate; beyond this the cell size grows (a crowd
/// spread over kilometres still gets a bounded grid).
const MAX_CELLS: usize = 1 << 22;

/// Points bucketed into square cells. Ground-plane points are `Vec2(x, z)`.
#[derive(Clone, Debug)]
pub(crate) struct Grid {
    origin: Vec2,
    cell: f32,
    nx: usize,
    nz: usize,
    /// `starts[c]..starts[c + 1]` indexes `items` for cell `c` (row-major, x fastest).
    starts: Vec<u32>,
    /// Point indices grouped by cell, ascending within a cell.
    items: Vec<u32>,
}

impl Grid {
    /// Buckets `points` into cells of side at least `cell` metres.
    /// Non-finite points are left out (they have no neighbours).
    pub(crate) fn build(points: &[Vec2], cell: f32) -> Grid {
        let mut lo = Vec2::splat(f32::INFINITY);
        let mut hi = Vec2::splat(f32::NEG_INFINITY);
        for p in points.iter().filter(|p| p.is_finite()) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if !lo.is_finite() {
            return Grid { origin: Vec2::ZERO, cell: 1.0, nx: 1, nz: 1, starts: vec![0, 0], items: Vec::new() };
        }
        let mut cell = if cell.is_finite() && cell > 0.0 { cell } else { 1.0 };
        // In f64, and saturating: points 1e37 m apart (or at -3e38 and +3e38,
        // whose span overflows f32) still give a count the loop below halves.
        let span = hi.as_dvec2() - lo.as_dvec2();
        let dims = |cell: f32| {
            let nx = ((span.x / f64::from(cell)).floor() as usize).saturating_add(1);
            let nz = ((span.y / f64::from(cell)).floor() as usize).saturating_add(1);
            (nx, nz)
        };
        let (mut nx, mut nz) = dims(cell);
        while nx.saturating_mul(nz) > MAX_CELLS {
            cell *= 2.0;
            (nx, nz) = dims(cell);
        }
        let mut grid = Grid { origin: lo, cell, nx, nz, starts: vec![0; nx * nz + 1], items: Vec::new() };
        let cells: Vec<usize> = points.iter().map(|p| grid.cell_of(*p)).collect();
        for &c in &cells {
            if c != usize::MAX {
                grid.starts[c + 1] += 1;
            }
        }
        for c in 0..nx * nz {
            grid.starts[c + 1] += grid.starts[c];
        }
        let mut fill = grid.starts.clone();
        grid.items = vec![0; grid.starts[nx * nz] as usize];
        for (i, &c) in cells.iter().enumerate() {
            if c != usize::MAX {
                grid.items[fill[c] as usize] = i as u32;
                fill[c] += 1;
            }
        }
        grid
    }

    fn cell_of(&self, p: Vec2) -> usize {
        if !p.is_finite() {
            return usize::MAX;
        }
        let (ix, iz) = self.coords(p);
        iz * self.nx + ix
    }

    fn coords(&self, p: Vec2) -> (usize, usize) {
        let q = (p - self.origin) / self.cell;
        let ix = (q.x.floor().max(0.0) as usize).min(self.nx - 1);
        let iz = (q.y.floor().max(0.0) as usize).min(self.nz - 1);
        (ix, iz)
    }

    /// Point indices in cell order: slot `k` holds point `items()[k]`.
    /// Callers copy per-point data into this order so a query reads memory
    /// that neighbours share.
    pub(crate) fn items(&self) -> &[u32] {
        &self.items
    }

    /// Calls `f` with the index of every point that may lie within `radius`
    /// of `p` (a superset: callers test the distance), in a fixed order.
    #[cfg(test)] // the simulation queries slots (`for_each_slot_near`)
    pub(crate) fn for_each_near(&self, p: Vec2, radius: f32, mut f: impl FnMut(usize)) {
        self.for_each_slot_near(p, radius, |k| f(self.items[k] as usize));
    }

    /// Like [`Grid::for_each_near`] but gives slots (positions in
    /// [`Grid::items`]), in increasing slot order within each cell row.
    pub(crate) fn for_each_slot_near(&self, p: Vec2, radius: f32, mut f: impl FnMut(usize)) {
        if !p.is_finite() || self.items.is_empty() {
            return;
        }
        let (x0, z0) = self.coords(p - Vec2::splat(radius));
        let (x1, z1) = self.coords(p + Vec2::splat(radius));
        for iz in z0..=z1 {
            let row = iz * self.nx;
            // Cells of one row are contiguous in `items`.
            for k in self.starts[row + x0] as usize..self.starts[row + x1 + 1] as usize {
                f(k);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(points: &[Vec2], p: Vec2, r: f32) -> Vec<usize> {
        (0..points.len()).filter(|&i| points[i].distance(p) <= r).collect()
    }

    #[test]
    fn finds_every_neighbour() {
        let mut points = Vec::new();
        for i in 0..500u32 {
            // Deterministic scatter without a generator.
            let a = (i as f32 * 2.399_963).sin() * 20.0;
            let b = (i as f32 * 1.618_034).cos() * 13.0;
            points.push(Vec2::new(a, b));
        }
        let grid = Grid::build(&points, 2.5);
        for q in [Vec2::ZERO, Vec2::new(19.0, -12.0), Vec2::new(-40.0, 3.0), Vec2::new(5.0, 5.0)] {
            let mut got = Vec::new();
            grid.for_each_near(q, 3.0, |i| {
                if points[i].distance(q) <= 3.0 {
                    got.push(i)
                }
            });
            got.sort_unstable();
            assert_eq!(got, brute(&points, q, 3.0));
        }
    }

    #[test]
    fn huge_spread_caps_cells() {
        let points = [Vec2::new(-1e7, -1e7), Vec2::new(1e7, 1e7), Vec2::ZERO];
        let grid = Grid::build(&points, 0.5);
        assert!(grid.nx * grid.nz <= MAX_CELLS);
        let mut got = Vec::new();
        grid.for_each_near(Vec2::ZERO, 1.0, |i| got.push(i));
        assert!(got.contains(&2));
    }

    #[test]
    fn spans_past_usize_and_f32_cap_cells() {
        // Found by the sim_scene fuzzer (docs/fuzzing.md): an agent at z = 1e37
        // made the cell count wrap to 0 and `build` index past its cells.
        for points in
            [vec![Vec2::ZERO, Vec2::new(12.0, 1e37)], vec![Vec2::new(-3e38, -3e38), Vec2::new(3e38, 3e38), Vec2::ZERO]]
        {
            let grid = Grid::build(&points, 0.6);
            assert!(grid.nx >= 1 && grid.nz >= 1 && grid.nx * grid.nz <= MAX_CELLS);
            let mut got = Vec::new();
            grid.for_each_near(Vec2::ZERO, 1.0, |i| got.push(i));
            assert!(got.contains(&0) || got.contains(&2), "{got:?}");
        }
    }

    #[test]
    fn empty_and_nan() {
        let grid = Grid::build(&[], 1.0);
        grid.for_each_near(Vec2::ZERO, 1.0, |_| panic!("no points"));
        let grid = Grid::build(&[Vec2::NAN, Vec2::ONE], 1.0);
        let mut got = Vec::new();
        grid.for_each_near(Vec2::ONE, 1.0, |i| got.push(i));
        assert_eq!(got, vec![1]);
    }
}
