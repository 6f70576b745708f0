//! Connected regions of an occupancy grid, by two-pass union-find labelling.
//!
//! Rosenfeld & Pfaltz, "Sequential operations in digital picture processing", JACM 13 (1966):
//! one raster scan gives each member cell the provisional label of an already-scanned
//! neighbour (west, and north-west, north, north-east for 8-connectivity), recording which
//! provisional labels meet; a second scan replaces each by its set's final label. Final labels
//! are numbered in raster order of each region's first cell, so they are deterministic.
//! Used by `remove_islands` (occupied regions) and `keep_largest_free_region` (free regions),
//! inside the coverage search, where it runs once per probe: hence two scans rather than a
//! flood fill's queue.

/// Which neighbours join two cells into one region.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Connectivity {
    /// Edge neighbours only.
    Four,
    /// Edge and corner neighbours.
    Eight,
}

/// Regions of the cells where `member` is true.
#[derive(Debug, Clone)]
pub struct Regions {
    /// Region label of each cell, [`Regions::NONE`] for cells outside every region.
    pub label: Vec<u32>,
    /// Number of cells in each region, indexed by label.
    pub sizes: Vec<usize>,
}

impl Regions {
    /// The label of cells that belong to no region.
    pub const NONE: u32 = u32::MAX;
}

/// Disjoint sets of provisional labels; the smaller label is always the root, so the result
/// does not depend on the order of unions.
struct Sets(Vec<u32>);

impl Sets {
    fn make(&mut self) -> u32 {
        let id = self.0.len() as u32;
        self.0.push(id);
        id
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let grandparent = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = grandparent;
            x = grandparent;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) -> u32 {
        let (ra, rb) = (self.find(a), self.find(b));
        let (root, child) = (ra.min(rb), ra.max(rb));
        self.0[child as usize] = root;
        root
    }
}

/// Label the connected regions of `member` cells.
pub fn label_regions(
    member: &[bool],
    rows: usize,
    cols: usize,
    connectivity: Connectivity,
) -> Regions {
    let mut label = vec![Regions::NONE; member.len()];
    let mut sets = Sets(Vec::new());
    // Scan 1: provisional labels from already-scanned neighbours.
    for r in 0..rows {
        for c in 0..cols {
            let i = r * cols + c;
            if !member[i] {
                continue;
            }
            let mut own = Regions::NONE;
            // Neighbours inside one region mostly carry the same provisional label already:
            // those join nothing new, and skip the union's two finds.
            let join = |j: usize, own: &mut u32, sets: &mut Sets| {
                if member[j] {
                    let theirs = label[j];
                    *own = if *own == Regions::NONE || *own == theirs {
                        theirs
                    } else {
                        sets.union(*own, theirs)
                    };
                }
            };
            if c > 0 {
                join(i - 1, &mut own, &mut sets);
            }
            if r > 0 {
                join(i - cols, &mut own, &mut sets);
                if connectivity == Connectivity::Eight {
                    if c > 0 {
                        join(i - cols - 1, &mut own, &mut sets);
                    }
                    if c + 1 < cols {
                        join(i - cols + 1, &mut own, &mut sets);
                    }
                }
            }
            label[i] = if own == Regions::NONE {
                sets.make()
            } else {
                own
            };
        }
    }
    // Scan 2: final labels, numbered by first appearance.
    let mut final_of = vec![Regions::NONE; sets.0.len()];
    let mut sizes = Vec::new();
    for l in label.iter_mut().filter(|l| **l != Regions::NONE) {
        let root = sets.find(*l) as usize;
        if final_of[root] == Regions::NONE {
            final_of[root] = sizes.len() as u32;
            sizes.push(0);
        }
        *l = final_of[root];
        sizes[*l as usize] += 1;
    }
    Regions { label, sizes }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::VecDeque;

    /// Flood fill, the obviously correct reference.
    fn flood_fill(member: &[bool], rows: usize, cols: usize, eight: bool) -> Vec<u32> {
        let mut label = vec![Regions::NONE; member.len()];
        let mut next = 0;
        for start in 0..member.len() {
            if !member[start] || label[start] != Regions::NONE {
                continue;
            }
            label[start] = next;
            let mut queue = VecDeque::from([start]);
            while let Some(i) = queue.pop_front() {
                let (r, c) = ((i / cols) as isize, (i % cols) as isize);
                for dr in -1isize..=1 {
                    for dc in -1isize..=1 {
                        let diagonal = dr != 0 && dc != 0;
                        if (dr == 0 && dc == 0) || (diagonal && !eight) {
                            continue;
                        }
                        let (nr, nc) = (r + dr, c + dc);
                        if nr < 0 || nc < 0 || nr >= rows as isize || nc >= cols as isize {
                            continue;
                        }
                        let j = nr as usize * cols + nc as usize;
                        if member[j] && label[j] == Regions::NONE {
                            label[j] = next;
                            queue.push_back(j);
                        }
                    }
                }
            }
            next += 1;
        }
        label
    }

    #[test]
    fn diagonal_cells_join_only_under_eight_connectivity() {
        let m = [true, false, false, true];
        assert_eq!(
            label_regions(&m, 2, 2, Connectivity::Four).sizes,
            vec![1, 1]
        );
        assert_eq!(label_regions(&m, 2, 2, Connectivity::Eight).sizes, vec![2]);
    }

    proptest! {
        #[test]
        fn labels_equal_a_flood_fill(rows in 1usize..20, cols in 1usize..20, eight: bool,
                bits in prop::collection::vec(prop::bool::weighted(0.5), 400)) {
            let member = &bits[..rows * cols];
            let connectivity = if eight { Connectivity::Eight } else { Connectivity::Four };
            let regions = label_regions(member, rows, cols, connectivity);
            let expected = flood_fill(member, rows, cols, eight);
            prop_assert_eq!(&regions.label, &expected);
            for (id, &size) in regions.sizes.iter().enumerate() {
                prop_assert_eq!(size, expected.iter().filter(|&&l| l == id as u32).count());
            }
        }
    }
}
