//! Occupancy grids as images: black = occupied, white = free, row 0 at the top.

use std::path::Path;

use image::codecs::pnm::{PnmEncoder, PnmSubtype, SampleEncoding};
use image::{ExtendedColorType, GrayImage, ImageEncoder, ImageFormat, Luma};

use crate::grid::{OccupancyGrid, ScalarField};

/// Grey level written for occupied cells.
pub const OCCUPIED_GREY: u8 = 0;
/// Grey level written for free cells (ROS map_saver writes 254 for free).
pub const FREE_GREY: u8 = 254;

/// Open an image whose size (read from its header first) is within [`crate::grid::MAX_CELLS`]
/// pixels; errors name the file.
pub fn open_image(path: &Path) -> Result<image::DynamicImage, String> {
    let shown = path.display();
    let (w, h) =
        image::image_dimensions(path).map_err(|e| format!("cannot read image {shown}: {e}"))?;
    crate::grid::check_size(h as usize, w as usize).map_err(|e| format!("image {shown}: {e}"))?;
    image::open(path).map_err(|e| format!("cannot read image {shown}: {e}"))
}

/// Read an image as darkness in [0, 1]: (max − luma) / max at 16-bit precision.
pub fn read_darkness(path: &Path) -> Result<ScalarField, String> {
    let img = open_image(path)?;
    let luma = img.into_luma16();
    let (cols, rows) = (luma.width() as usize, luma.height() as usize);
    let values = luma
        .pixels()
        .map(|p| f64::from(u16::MAX - p.0[0]) / f64::from(u16::MAX))
        .collect();
    Ok(ScalarField { cols, rows, values })
}

/// The grid as an 8-bit grey image.
pub fn to_gray_image(grid: &OccupancyGrid) -> GrayImage {
    GrayImage::from_fn(grid.cols as u32, grid.rows as u32, |x, y| {
        Luma([if grid.get(y as usize, x as usize) {
            OCCUPIED_GREY
        } else {
            FREE_GREY
        }])
    })
}

/// The grid as PNG file bytes (deterministic: same grid, same bytes).
pub fn encode_png(grid: &OccupancyGrid) -> Result<Vec<u8>, String> {
    let mut out = std::io::Cursor::new(Vec::new());
    to_gray_image(grid)
        .write_to(&mut out, ImageFormat::Png)
        .map_err(|e| format!("cannot encode PNG: {e}"))?;
    Ok(out.into_inner())
}

/// Write the grid as a PNG or a binary PGM (P5, what ROS map_server and Stage read) file,
/// chosen by the extension (`.png`, `.pgm`).
pub fn write_image(grid: &OccupancyGrid, path: &Path) -> Result<(), String> {
    let cannot = |e: &dyn std::fmt::Display| format!("cannot write {}: {e}", path.display());
    let image = to_gray_image(grid);
    match ImageFormat::from_path(path) {
        Ok(ImageFormat::Png) => image
            .save_with_format(path, ImageFormat::Png)
            .map_err(|e| cannot(&e)),
        Ok(ImageFormat::Pnm) => {
            let file = std::fs::File::create(path).map_err(|e| cannot(&e))?;
            PnmEncoder::new(std::io::BufWriter::new(file))
                .with_subtype(PnmSubtype::Graymap(SampleEncoding::Binary))
                .write_image(
                    image.as_raw(),
                    image.width(),
                    image.height(),
                    ExtendedColorType::L8,
                )
                .map_err(|e| cannot(&e))
        }
        _ => Err(format!(
            "{}: expected a .png or .pgm file name",
            path.display()
        )),
    }
}
