//! Bindings of `sitgen_core::mission`.

use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sitgen_core::mission::astar;

/// Cells (column, row) from start to goal, and the length in cells.
type PathAndLength = (Vec<(usize, usize)>, f64);

/// A* with the MovingAI rules on `blocked` (row 0 = top); cells are (column, row). Returns
/// (cells, length in cells), or None when there is no path.
#[pyfunction]
fn shortest_path(
    py: Python<'_>,
    blocked: PyReadonlyArray2<'_, bool>,
    start: (usize, usize),
    goal: (usize, usize),
) -> Option<PathAndLength> {
    let shape = blocked.shape();
    let (rows, cols) = (shape[0], shape[1]);
    let cells: Vec<bool> = blocked.as_array().iter().copied().collect();
    py.detach(|| astar::shortest_path(&cells, rows, cols, start, goal))
        .map(|p| (p.cells, p.length))
}

/// Lengths (in cells) of the shortest paths for many (start, goal) cell pairs on one grid,
/// searched one after another with reused work arrays; None where there is no path. For
/// benchmarks and batch checks.
#[pyfunction]
fn shortest_path_lengths(
    py: Python<'_>,
    blocked: PyReadonlyArray2<'_, bool>,
    problems: Vec<((usize, usize), (usize, usize))>,
) -> Vec<Option<f64>> {
    let shape = blocked.shape();
    let (rows, cols) = (shape[0], shape[1]);
    let cells: Vec<bool> = blocked.as_array().iter().copied().collect();
    py.detach(|| {
        let mut search = astar::PathSearch::new(&cells, rows, cols);
        problems
            .iter()
            .map(|&(start, goal)| search.shortest_path(start, goal).map(|p| p.length))
            .collect()
    })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(shortest_path, m)?)?;
    m.add_function(wrap_pyfunction!(shortest_path_lengths, m)?)?;
    Ok(())
}
