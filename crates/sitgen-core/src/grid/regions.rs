//! Connected regions of an occupancy grid, by breadth-first flood fill.
//!
//! Used by `remove_islands` (occupied regions) and `keep_largest_free_region` (free regions).
//! Labels are assigned in raster order of each region's first cell, so they are deterministic.

use std::collections::VecDeque;

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
    /// Region label of each cell, `None` for cells outside every region.
    pub label: Vec<Option<u32>>,
    /// Number of cells in each region, indexed by label.
    pub sizes: Vec<usize>,
}

/// Label the connected regions of `member` cells.
pub fn label_regions(
    member: &[bool],
    rows: usize,
    cols: usize,
    connectivity: Connectivity,
) -> Regions {
    let mut label = vec![None; member.len()];
    let mut sizes = Vec::new();
    let mut queue = VecDeque::new();
    let offsets: &[(isize, isize)] = match connectivity {
        Connectivity::Four => &[(-1, 0), (1, 0), (0, -1), (0, 1)],
        Connectivity::Eight => &[
            (-1, -1),
            (-1, 0),
            (-1, 1),
            (0, -1),
            (0, 1),
            (1, -1),
            (1, 0),
            (1, 1),
        ],
    };
    for start in 0..member.len() {
        if !member[start] || label[start].is_some() {
            continue;
        }
        let id = sizes.len() as u32;
        let mut size = 0usize;
        label[start] = Some(id);
        queue.push_back(start);
        while let Some(i) = queue.pop_front() {
            size += 1;
            let (r, c) = ((i / cols) as isize, (i % cols) as isize);
            for &(dr, dc) in offsets {
                let (nr, nc) = (r + dr, c + dc);
                if nr < 0 || nc < 0 || nr >= rows as isize || nc >= cols as isize {
                    continue;
                }
                let j = nr as usize * cols + nc as usize;
                if member[j] && label[j].is_none() {
                    label[j] = Some(id);
                    queue.push_back(j);
                }
            }
        }
        sizes.push(size);
    }
    Regions { label, sizes }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagonal_cells_join_only_under_eight_connectivity() {
        let m = [true, false, false, true];
        assert_eq!(
            label_regions(&m, 2, 2, Connectivity::Four).sizes,
            vec![1, 1]
        );
        assert_eq!(label_regions(&m, 2, 2, Connectivity::Eight).sizes, vec![2]);
    }
}
