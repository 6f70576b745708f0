//! Bindings of `sitgen_core::interchange`.

use std::path::PathBuf;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use sitgen_core::grid::{Map, OccupancyGrid};
use sitgen_core::interchange::{barn, image, maps, ros};

pub(crate) fn to_map(occupied: &PyReadonlyArray2<'_, bool>, resolution_m: f64) -> PyResult<Map> {
    let shape = occupied.shape();
    let cells = occupied.as_array().iter().copied().collect();
    Ok(Map {
        grid: OccupancyGrid {
            rows: shape[0],
            cols: shape[1],
            cells,
        },
        resolution_m,
    })
}

/// Write an occupancy array as a PNG or PGM image (by extension), and a ROS map_server YAML
/// beside it when `yaml_path` is given.
#[pyfunction]
#[pyo3(signature = (occupied, resolution_m, image_path, yaml_path=None))]
fn write_map(
    occupied: PyReadonlyArray2<'_, bool>,
    resolution_m: f64,
    image_path: PathBuf,
    yaml_path: Option<PathBuf>,
) -> PyResult<()> {
    let map = to_map(&occupied, resolution_m)?;
    image::write_image(&map.grid, &image_path).map_err(PyOSError::new_err)?;
    if let Some(yaml) = yaml_path {
        ros::write_map_yaml(&map, &yaml, &image_path).map_err(PyOSError::new_err)?;
    }
    Ok(())
}

/// (occupied array, resolution in metres, origin (x, y, yaw)).
type LoadedMapTuple<'py> = (Bound<'py, PyAny>, f64, (f64, f64, f64));

/// Load a map file (ROS YAML, PNG, PGM, MovingAI `.map`): (occupied array, resolution in
/// metres, origin (x, y, yaw) of a ROS map). `resolution_m` is used for formats that carry none.
#[pyfunction]
#[pyo3(signature = (path, resolution_m=0.1, unknown_free=false))]
fn load_map<'py>(
    py: Python<'py>,
    path: PathBuf,
    resolution_m: f64,
    unknown_free: bool,
) -> PyResult<LoadedMapTuple<'py>> {
    let unknown = if unknown_free {
        maps::Unknown::Free
    } else {
        maps::Unknown::Occupied
    };
    let loaded =
        maps::load_map_with_origin(&path, resolution_m, unknown).map_err(PyOSError::new_err)?;
    let g = loaded.map.grid;
    let occupied = PyArray1::from_vec(py, g.cells).reshape([g.rows, g.cols])?;
    let [x, y, yaw] = loaded.origin;
    Ok((occupied.into_any(), loaded.map.resolution_m, (x, y, yaw)))
}

/// BARN world `index` as a situation (JSON): `grid` its 30 × 30 cells row-major with BARN's
/// (row, column) indices (non-zero: obstacle), `path` its official path as (row, column).
#[pyfunction]
fn barn_situation(grid: &[u8], path: Vec<(usize, usize)>, index: u64) -> PyResult<String> {
    let situation = barn::barn_situation(grid, &path, index)
        .map_err(|e| crate::SpecError::new_err(e.to_string()))?;
    Ok(situation.to_json())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(barn_situation, m)?)?;
    m.add_function(wrap_pyfunction!(write_map, m)?)?;
    m.add_function(wrap_pyfunction!(load_map, m)?)?;
    Ok(())
}
