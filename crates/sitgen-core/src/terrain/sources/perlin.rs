//! # `perlin` source
//!
//! **What it makes.** A scalar field of fractal Perlin noise: `octaves` layers of improved
//! noise, octave o sampled at frequency lacunarityᵒ / `scale_m` with amplitude
//! persistenceᵒ, summed, divided by the sum of amplitudes and mapped from [−1, 1] to [0, 1].
//! The seed moves the sampling window to a random offset in the 256-periodic noise space (the
//! permutation is Perlin's fixed one, so `sitgen.perlin` stays the reference function).
//!
//! **Why.** The paper's terrain base: smooth, natural-looking variation that thresholding
//! turns into blobs of rock, and pixelising into rubble or blocks.
//!
//! **Parameters.**
//! - `octaves` (count, default 6, in [1, 16]): noise layers summed.
//! - `persistence` (ratio, default 0.5, in [0, 1]): amplitude ratio between octaves.
//! - `lacunarity` (ratio, default 2.0, in [1, 8]): frequency ratio between octaves.
//! - `scale_m` (metres, default 10.0, in (0, 10000]): feature size of the first octave (one
//!   noise lattice cell).
//!
//! **Source.** K. Perlin, "Improving Noise", SIGGRAPH 2002; fractal sums as in Musgrave's
//! fBm (Ebert et al., *Texturing and Modeling*, 1994); Arnold & Alexander (2013) §3.

use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::ScalarField;
use crate::rng::ChoiceSource;
use crate::terrain::noise::{add_perlin_in_cube, Axis, Corners};
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// Parameters of the `perlin` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Perlin {
    /// Noise layers summed, in [1, 16]. Default 6.
    #[serde(default = "default_octaves")]
    pub octaves: u32,
    /// Amplitude ratio between successive octaves, in [0, 1]. Default 0.5.
    #[serde(default = "default_persistence")]
    pub persistence: f64,
    /// Frequency ratio between successive octaves, in [1, 8]. Default 2.0.
    #[serde(default = "default_lacunarity")]
    pub lacunarity: f64,
    /// Feature size of the first octave (one noise lattice cell), metres, in (0, 10000].
    /// Default 10.0.
    #[serde(default = "default_scale_m")]
    pub scale_m: f64,
}

fn default_octaves() -> u32 {
    6
}
fn default_persistence() -> f64 {
    0.5
}
fn default_lacunarity() -> f64 {
    2.0
}
fn default_scale_m() -> f64 {
    10.0
}

impl Default for Perlin {
    fn default() -> Self {
        Self {
            octaves: default_octaves(),
            persistence: default_persistence(),
            lacunarity: default_lacunarity(),
            scale_m: default_scale_m(),
        }
    }
}

impl Source for Perlin {
    fn output(&self) -> LayerKind {
        LayerKind::Field
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        if !(1..=16).contains(&self.octaves) {
            return Err(SpecError::new(
                join(path, "octaves"),
                format!("{} is not in [1, 16]", self.octaves),
            ));
        }
        SpecError::check_in(&join(path, "persistence"), self.persistence, 0.0, 1.0)?;
        SpecError::check_in(&join(path, "lacunarity"), self.lacunarity, 1.0, 8.0)?;
        SpecError::check_positive(&join(path, "scale_m"), self.scale_m, 10_000.0)
    }

    fn generate(&self, extent: Extent, choices: &mut ChoiceSource) -> Result<Layer, String> {
        let offset = [
            choices.uniform(0.0, 256.0),
            choices.uniform(0.0, 256.0),
            choices.uniform(0.0, 256.0),
        ];
        let octaves = self.octave_table();
        let amplitude_sum: f64 = octaves.iter().map(|o| o.1).sum();
        let Extent {
            rows,
            cols,
            resolution_m: res,
        } = extent;
        // A column's x, and so its part of each octave's noise, is the same in every row; so
        // are the runs of columns in one lattice cell.
        let x_parts: Vec<XParts> = octaves
            .iter()
            .map(|&(frequency, _)| {
                XParts::new((0..cols).map(|c| {
                    let x = (c as f64 + 0.5) * res / self.scale_m;
                    Axis::new(x * frequency + offset[0])
                }))
            })
            .collect();
        let z = Axis::new(offset[2]);
        let mut values = vec![0.0; rows * cols];
        crate::parallel::install(|| {
            values
                .par_chunks_mut(cols)
                .enumerate()
                .for_each(|(r, row)| {
                    let y = (rows as f64 - r as f64 - 0.5) * res / self.scale_m;
                    // Octave by octave along the row, each cell's sum in the same order as cell
                    // by cell: the row shares y and z, and a run of cells shares a lattice
                    // cube, whose corners are hashed once and whose gradients pick the same
                    // terms.
                    row.fill(0.0);
                    for (&(frequency, amplitude), xs) in octaves.iter().zip(&x_parts) {
                        let y = Axis::new(y * frequency + offset[1]);
                        for &(start, end, first) in &xs.runs {
                            let corners = Corners::hash(first, y, z);
                            add_perlin_in_cube(
                                &corners,
                                &xs.offsets[start..end],
                                &xs.fades[start..end],
                                y,
                                z,
                                amplitude,
                                &mut row[start..end],
                            );
                        }
                    }
                    for out in row.iter_mut() {
                        let sum = *out;
                        *out = if amplitude_sum > 0.0 {
                            (0.5 * (sum / amplitude_sum + 1.0)).clamp(0.0, 1.0)
                        } else {
                            0.5
                        };
                    }
                });
        });
        Ok(Layer::Field(ScalarField { cols, rows, values }))
    }
}

/// One octave's x parts of a map's columns, with the runs of columns that share a lattice
/// cell.
struct XParts {
    offsets: Vec<f64>,
    fades: Vec<f64>,
    /// `[start, end)` of each run of columns in the same lattice cell, in order, with the x
    /// part of its first column (whose cell names the run's cubes).
    runs: Vec<(usize, usize, Axis)>,
}

impl XParts {
    fn new(axes: impl Iterator<Item = Axis>) -> Self {
        let (mut offsets, mut fades) = (Vec::new(), Vec::new());
        let mut runs: Vec<(usize, usize, Axis)> = Vec::new();
        for (c, a) in axes.enumerate() {
            offsets.push(a.offset());
            fades.push(a.fade());
            match runs.last_mut() {
                Some(run) if run.2.cell() == a.cell() => run.1 = c + 1,
                _ => runs.push((c, c + 1, a)),
            }
        }
        Self {
            offsets,
            fades,
            runs,
        }
    }
}

impl Perlin {
    /// (frequency, amplitude) of each octave.
    fn octave_table(&self) -> Vec<(f64, f64)> {
        let (mut frequency, mut amplitude) = (1.0, 1.0);
        (0..self.octaves)
            .map(|_| {
                let o = (frequency, amplitude);
                frequency *= self.lacunarity;
                amplitude *= self.persistence;
                o
            })
            .collect()
    }
}
