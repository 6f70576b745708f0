//! Ken Perlin's improved noise (2002), bit for bit.
//!
//! K. Perlin, "Improving Noise", SIGGRAPH 2002, and its reference implementation: a fixed
//! permutation of 0..255, the quintic fade 6t⁵ − 15t⁴ + 10t³, and twelve gradient directions
//! (the edges of a cube) picked by the low four bits of the hash, four of them repeated.
//! The arithmetic is written in the reference's order so that every `f64` result is identical
//! to it (checked against values from the reference in the tests). Lattice points give 0;
//! the lattice repeats every 256 units; output lies roughly in [−1, 1].

/// Perlin's published permutation of 0..255.
const PERMUTATION: [u8; 256] = [
    151, 160, 137, 91, 90, 15, 131, 13, 201, 95, 96, 53, 194, 233, 7, 225, 140, 36, 103, 30, 69,
    142, 8, 99, 37, 240, 21, 10, 23, 190, 6, 148, 247, 120, 234, 75, 0, 26, 197, 62, 94, 252, 219,
    203, 117, 35, 11, 32, 57, 177, 33, 88, 237, 149, 56, 87, 174, 20, 125, 136, 171, 168, 68, 175,
    74, 165, 71, 134, 139, 48, 27, 166, 77, 146, 158, 231, 83, 111, 229, 122, 60, 211, 133, 230,
    220, 105, 92, 41, 55, 46, 245, 40, 244, 102, 143, 54, 65, 25, 63, 161, 1, 216, 80, 73, 209, 76,
    132, 187, 208, 89, 18, 169, 200, 196, 135, 130, 116, 188, 159, 86, 164, 100, 109, 198, 173,
    186, 3, 64, 52, 217, 226, 250, 124, 123, 5, 202, 38, 147, 118, 126, 255, 82, 85, 212, 207, 206,
    59, 227, 47, 16, 58, 17, 182, 189, 28, 42, 223, 183, 170, 213, 119, 248, 152, 2, 44, 154, 163,
    70, 221, 153, 101, 155, 167, 43, 172, 9, 129, 22, 39, 253, 19, 98, 108, 110, 79, 113, 224, 232,
    178, 185, 112, 104, 218, 246, 97, 228, 251, 34, 242, 193, 238, 210, 144, 12, 191, 179, 162,
    241, 81, 51, 145, 235, 249, 14, 239, 107, 49, 192, 214, 31, 181, 199, 106, 157, 184, 84, 204,
    176, 115, 121, 50, 45, 127, 4, 150, 254, 138, 236, 205, 93, 222, 114, 67, 29, 24, 72, 243, 141,
    128, 195, 78, 66, 215, 61, 156, 180,
];

/// The permutation doubled, so that `P[i + 1]` needs no wrap for i ≤ 255 + 255.
const P: [usize; 512] = {
    let mut p = [0usize; 512];
    let mut i = 0;
    while i < 512 {
        p[i] = PERMUTATION[i % 256] as usize;
        i += 1;
    }
    p
};

/// The quintic fade curve 6t⁵ − 15t⁴ + 10t³.
#[inline]
pub fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
fn lerp(t: f64, a: f64, b: f64) -> f64 {
    a + t * (b - a)
}

/// Dot product of (x, y, z) with the gradient the hash's low four bits select: ±u ± v with u
/// and v picked from x, y, z as the reference's branches pick them ([`GRADIENTS`]). The picks
/// and signs come from a table and the signs are applied to the sign bit (exactly what
/// negation does), so the eight gradients of a point cost no unpredictable branches.
#[inline]
fn grad(hash: usize, x: f64, y: f64, z: f64) -> f64 {
    let g = GRADIENTS[hash & 15];
    let p = [x, y, z];
    let u = f64::from_bits(p[g.u as usize].to_bits() ^ g.u_sign);
    let v = f64::from_bits(p[g.v as usize].to_bits() ^ g.v_sign);
    u + v
}

/// One gradient of [`grad`]: which coordinates (0 = x, 1 = y, 2 = z) it adds, and the sign
/// bit each is flipped by.
#[derive(Clone, Copy)]
struct Gradient {
    u: u8,
    v: u8,
    u_sign: u64,
    v_sign: u64,
}

/// The reference's `grad` as a table: u is x for h < 8, else y; v is y for h < 4, x for h =
/// 12 or 14, else z; u is negated when bit 0 is set, v when bit 1 is.
const GRADIENTS: [Gradient; 16] = {
    let mut table = [Gradient {
        u: 0,
        v: 0,
        u_sign: 0,
        v_sign: 0,
    }; 16];
    let mut h = 0;
    while h < 16 {
        table[h] = Gradient {
            u: if h < 8 { 0 } else { 1 },
            v: if h < 4 {
                1
            } else if h == 12 || h == 14 {
                0
            } else {
                2
            },
            u_sign: if h & 1 == 0 { 0 } else { 1 << 63 },
            v_sign: if h & 2 == 0 { 0 } else { 1 << 63 },
        };
        h += 1;
    }
    table
};

/// `x.floor()` for finite |x| < 2⁶³, without the libm call that baseline x86-64 (no SSE4.1
/// `roundsd`) makes for `floor`: the same bits, signed zero included, so results stay
/// bit-exact; noise runs per cell per octave.
#[inline]
fn floor(x: f64) -> f64 {
    let truncated = x as i64 as f64;
    if truncated > x {
        truncated - 1.0
    } else {
        truncated.copysign(x)
    }
}

/// One coordinate's part of the noise: the lattice cell holding it (wrapped to the 256-periodic
/// lattice), its offset in that cell and the offset's fade. The cells of a grid row share y and
/// z, so a caller may compute those parts once per row ([`perlin_at`]).
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    cell: usize,
    offset: f64,
    fade: f64,
}

impl Axis {
    /// The part of coordinate `v`.
    #[inline]
    pub fn new(v: f64) -> Self {
        let f = floor(v);
        let offset = v - f;
        Self {
            cell: (f as i64 & 255) as usize,
            offset,
            fade: fade(offset),
        }
    }

    /// The lattice cell, wrapped to the permutation's 256.
    pub fn cell(&self) -> usize {
        self.cell
    }

    /// The offset in the cell, in [0, 1).
    pub fn offset(&self) -> f64 {
        self.offset
    }

    /// The offset's fade.
    pub fn fade(&self) -> f64 {
        self.fade
    }
}

/// Improved noise at (x, y, z).
pub fn perlin(x: f64, y: f64, z: f64) -> f64 {
    perlin_at(Axis::new(x), Axis::new(y), Axis::new(z))
}

/// Improved noise at the point whose coordinates' parts are `x`, `y`, `z`.
#[inline]
pub fn perlin_at(x: Axis, y: Axis, z: Axis) -> f64 {
    perlin_in(&Corners::hash(x, y, z), x, y, z)
}

/// The hashes of the eight corners of one unit cube of the lattice: every point in the cube
/// shares them, so a row of cells that stays in one cube hashes once ([`add_perlin_in_cube`]).
#[derive(Debug, Clone, Copy)]
pub struct Corners {
    /// The cube's cells on the x axis, and on y, z: which cube this is.
    cube: (usize, usize, usize),
    /// The gradient hashes of corners (x, y, z) … (x+1, y+1, z+1), in the reference's order.
    aa: usize,
    ba: usize,
    ab: usize,
    bb: usize,
    aa1: usize,
    ba1: usize,
    ab1: usize,
    bb1: usize,
}

impl Corners {
    /// Hash the eight corners of the cube holding the point whose parts are `x`, `y`, `z`.
    #[inline]
    pub fn hash(x: Axis, y: Axis, z: Axis) -> Self {
        let (xi, yi, zi) = (x.cell, y.cell, z.cell);
        let a = P[xi] + yi;
        let aa = P[a] + zi;
        let ab = P[a + 1] + zi;
        let b = P[xi + 1] + yi;
        let ba = P[b] + zi;
        let bb = P[b + 1] + zi;
        Self {
            cube: (xi, yi, zi),
            aa: P[aa],
            ba: P[ba],
            ab: P[ab],
            bb: P[bb],
            aa1: P[aa + 1],
            ba1: P[ba + 1],
            ab1: P[ab + 1],
            bb1: P[bb + 1],
        }
    }
}

/// Improved noise at the point whose coordinates' parts are `x`, `y`, `z`, in the cube whose
/// corners are `corners`: the eight gradients' contributions blended by the fades.
#[inline]
pub fn perlin_in(corners: &Corners, x: Axis, y: Axis, z: Axis) -> f64 {
    debug_assert_eq!(corners.cube, (x.cell, y.cell, z.cell));
    let (u, v, w) = (x.fade, y.fade, z.fade);
    let (x, y, z) = (x.offset, y.offset, z.offset);
    let k = corners;
    lerp(
        w,
        lerp(
            v,
            lerp(u, grad(k.aa, x, y, z), grad(k.ba, x - 1.0, y, z)),
            lerp(
                u,
                grad(k.ab, x, y - 1.0, z),
                grad(k.bb, x - 1.0, y - 1.0, z),
            ),
        ),
        lerp(
            v,
            lerp(
                u,
                grad(k.aa1, x, y, z - 1.0),
                grad(k.ba1, x - 1.0, y, z - 1.0),
            ),
            lerp(
                u,
                grad(k.ab1, x, y - 1.0, z - 1.0),
                grad(k.bb1, x - 1.0, y - 1.0, z - 1.0),
            ),
        ),
    )
}

/// Adds `amplitude ×` [`perlin_in`] to `out[i]` for the points whose x parts are `x_offset[i]`
/// and `x_fade[i]`, all in one lattice cube (`corners`, with `y` and `z`): the same bits as
/// point by point. Along a row of a map every point of a run shares the cube, y and z, so each
/// corner's gradient picks the same coordinates and signs for the whole run: a few loops over
/// the run without a table lookup or a branch per point, which the compiler turns into vector
/// code.
pub fn add_perlin_in_cube(
    corners: &Corners,
    x_offset: &[f64],
    x_fade: &[f64],
    y: Axis,
    z: Axis,
    amplitude: f64,
    out: &mut [f64],
) {
    debug_assert_eq!((corners.cube.1, corners.cube.2), (y.cell, z.cell));
    debug_assert!(x_offset.len() == out.len() && x_fade.len() == out.len());
    const LANES: usize = 64;
    let (v, w) = (y.fade, z.fade);
    let (y, z) = (y.offset, z.offset);
    let (y1, z1) = (y - 1.0, z - 1.0);
    let k = corners;
    for ((xs, fades), out) in x_offset
        .chunks(LANES)
        .zip(x_fade.chunks(LANES))
        .zip(out.chunks_mut(LANES))
    {
        let n = xs.len();
        let mut xs1 = [0.0; LANES];
        for (x1, &x) in xs1.iter_mut().zip(xs) {
            *x1 = x - 1.0;
        }
        let xs1 = &xs1[..n];
        let mut g = [[0.0; LANES]; 8];
        grads(k.aa, xs, y, z, &mut g[0][..n]);
        grads(k.ba, xs1, y, z, &mut g[1][..n]);
        grads(k.ab, xs, y1, z, &mut g[2][..n]);
        grads(k.bb, xs1, y1, z, &mut g[3][..n]);
        grads(k.aa1, xs, y, z1, &mut g[4][..n]);
        grads(k.ba1, xs1, y, z1, &mut g[5][..n]);
        grads(k.ab1, xs, y1, z1, &mut g[6][..n]);
        grads(k.bb1, xs1, y1, z1, &mut g[7][..n]);
        for (i, (out, &u)) in out.iter_mut().zip(fades).enumerate() {
            let noise = lerp(
                w,
                lerp(v, lerp(u, g[0][i], g[1][i]), lerp(u, g[2][i], g[3][i])),
                lerp(v, lerp(u, g[4][i], g[5][i]), lerp(u, g[6][i], g[7][i])),
            );
            *out += amplitude * noise;
        }
    }
}

/// [`grad`] of one corner for the points `(xs[i], y, z)`, into `out`: the table's picks and
/// sign flips once, then one loop (a constant where the gradient ignores x).
#[inline]
fn grads(hash: usize, xs: &[f64], y: f64, z: f64, out: &mut [f64]) {
    let g = GRADIENTS[hash & 15];
    let flip = |value: f64, sign: u64| f64::from_bits(value.to_bits() ^ sign);
    let picks = [y, z];
    match (g.u, g.v) {
        // u is x; v is y or z.
        (0, v) => {
            let v = flip(picks[v as usize - 1], g.v_sign);
            for (out, &x) in out.iter_mut().zip(xs) {
                *out = flip(x, g.u_sign) + v;
            }
        }
        // u is y; v is x.
        (_, 0) => {
            let u = flip(y, g.u_sign);
            for (out, &x) in out.iter_mut().zip(xs) {
                *out = u + flip(x, g.v_sign);
            }
        }
        // u is y; v is y or z: the same for every point.
        (_, v) => out.fill(flip(y, g.u_sign) + flip(picks[v as usize - 1], g.v_sign)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    // 3.14 is a published reference input, not an approximation of π.
    #[allow(clippy::approx_constant)]
    fn published_anchor_values() {
        assert_eq!(perlin(3.14, 42.0, 7.0), 0.13691995878400012);
        assert_eq!(perlin(-4.2, 10.0, 6.0), 0.14208000000000043);
        assert_eq!(perlin(-4.2, 10.0, 0.0), -0.14208000000000043);
        assert_eq!(perlin(0.5, 0.5, 0.5), -0.25);
        assert_eq!(perlin(0.1, 0.1, 0.1), 0.1861607143544832);
        assert_eq!(fade(0.75), 0.896484375);
        for i in -3..3 {
            assert_eq!(perlin(f64::from(i), 7.0, f64::from(-i)), 0.0);
        }
    }

    /// The reference's `grad`, branch by branch.
    fn reference_grad(hash: usize, x: f64, y: f64, z: f64) -> f64 {
        let h = hash & 15;
        let u = if h < 8 { x } else { y };
        let v = if h < 4 {
            y
        } else if h == 12 || h == 14 {
            x
        } else {
            z
        };
        (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
    }

    #[test]
    fn the_gradient_table_is_the_reference_s_branches_bit_for_bit() {
        let values = [0.0, -0.0, 0.25, -0.75, 1.0, 0.1, -0.3, 0.999];
        for hash in 0..512 {
            for &x in &values {
                for &y in &values {
                    for &z in &values {
                        assert_eq!(
                            grad(hash, x, y, z).to_bits(),
                            reference_grad(hash, x, y, z).to_bits(),
                            "hash {hash}, ({x}, {y}, {z})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn fast_floor_equals_floor() {
        for x in [
            -2.5,
            -2.0,
            -1e-300,
            -0.0,
            0.0,
            0.3,
            1.0,
            255.999,
            1e15 + 0.5,
            -1e15 - 0.5,
        ] {
            assert_eq!(floor(x).to_bits(), x.floor().to_bits(), "{x}");
        }
    }

    #[test]
    fn the_permutation_is_a_permutation() {
        let mut seen = [false; 256];
        PERMUTATION.iter().for_each(|&p| seen[p as usize] = true);
        assert!(seen.iter().all(|&s| s));
    }

    proptest::proptest! {
        #[test]
        fn a_cube_s_run_is_each_point_s_noise_bit_for_bit(
            cell in (0.0f64..300.0, -40.0f64..40.0, 0.0f64..256.0),
            xs in proptest::collection::vec(0.0f64..1.0, 0..150),
            amplitude in 0.0f64..2.0,
            start in -1.0f64..1.0,
        ) {
            // Points of one cube: the cube's corner plus offsets in [0, 1).
            let (cx, y, z) = (cell.0.floor(), Axis::new(cell.1), Axis::new(cell.2));
            let points: Vec<Axis> = xs.iter().map(|&dx| Axis::new(cx + dx)).collect();
            let Some(&first) = points.first() else { return Ok(()) };
            let corners = Corners::hash(first, y, z);
            let offsets: Vec<f64> = points.iter().map(|p| p.offset).collect();
            let fades: Vec<f64> = points.iter().map(|p| p.fade).collect();
            let mut run = vec![start; points.len()];
            add_perlin_in_cube(&corners, &offsets, &fades, y, z, amplitude, &mut run);
            for (p, r) in points.iter().zip(&run) {
                if p.cell != first.cell {
                    continue; // cx + dx rounded up to the next cube
                }
                let one = start + amplitude * perlin_in(&corners, *p, y, z);
                proptest::prop_assert_eq!(r.to_bits(), one.to_bits());
            }
        }
    }
}
