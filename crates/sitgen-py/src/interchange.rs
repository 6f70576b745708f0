//! Bindings of `sitgen_core::interchange`.

use std::path::PathBuf;

use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use sitgen_core::grid::{Map, OccupancyGrid};
use sitgen_core::interchange::{image, ros};

fn to_map(occupied: &PyReadonlyArray2<'_, bool>, resolution_m: f64) -> PyResult<Map> {
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

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(write_map, m)?)?;
    Ok(())
}
