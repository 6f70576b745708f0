//! Bindings of `sitgen_core::mission`.

use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use sitgen_core::control::route::RouteFollower;
use sitgen_core::mission::{self, astar, AtEnd};
use sitgen_core::rng::ChoiceSource;
use sitgen_core::situation::Situation;

use crate::SpecError;

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

/// The agent's route of situation `situation_json` continued past its last waypoint as the
/// mission plans routes, with the situation's own mission spec and a choice stream seeded by
/// `seed`: the new waypoints, or None where no route goes on from there.
#[pyfunction]
fn continued_route(situation_json: &str, seed: u64) -> PyResult<Option<Vec<(f64, f64)>>> {
    let situation =
        Situation::from_json(situation_json).map_err(|e| SpecError::new_err(e.to_string()))?;
    let map = situation
        .map
        .decode()
        .map_err(|e| SpecError::new_err(e.to_string()))?;
    let agent = &situation.robots[0];
    let from = agent
        .waypoints
        .last()
        .map_or((agent.start.x_m, agent.start.y_m), |w| (w[0], w[1]));
    let spec = &situation.provenance.spec.mission;
    let mut choices = ChoiceSource::stream(seed, "continued route");
    Ok(mission::continue_agent_route(&map, spec, from, &mut choices).ok())
}

/// Where a robot is on its route, as the built-in controllers follow one (the start, then
/// the waypoints, then `at_end`: `stop`, `reverse` or `loop`), switching to the next point
/// within `switch_m` metres: for a Python controller that follows a route as they do.
#[pyclass(name = "RouteFollower", module = "sitgen._core")]
pub struct PyRouteFollower(RouteFollower);

#[pymethods]
impl PyRouteFollower {
    #[new]
    fn new(
        start: (f64, f64),
        waypoints: Vec<(f64, f64)>,
        at_end: &str,
        switch_m: f64,
    ) -> PyResult<Self> {
        let at_end: AtEnd = serde_json::from_value(serde_json::Value::from(at_end))
            .map_err(|e| SpecError::new_err(format!("at_end: {e}")))?;
        Ok(Self(RouteFollower::through(
            start, &waypoints, at_end, switch_m,
        )))
    }

    /// The point to head for from `position`, after switching past every point within
    /// reach; None once a `stop` route is complete.
    fn target(&mut self, position: (f64, f64)) -> Option<(f64, f64)> {
        self.0.target(position)
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRouteFollower>()?;
    m.add_function(wrap_pyfunction!(continued_route, m)?)?;
    m.add_function(wrap_pyfunction!(shortest_path, m)?)?;
    m.add_function(wrap_pyfunction!(shortest_path_lengths, m)?)?;
    Ok(())
}
