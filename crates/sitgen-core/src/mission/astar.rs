//! A* shortest paths on an 8-connected grid, with the MovingAI movement rules.
//!
//! Hart, Nilsson & Raphael, "A Formal Basis for the Heuristic Determination of Minimum Cost
//! Paths", IEEE SSC 4(2), 1968. Moves go to the 8 neighbours; a straight move costs 1 and a
//! diagonal move √2; a diagonal move is allowed only when both cells it passes between are
//! free (no corner cutting), as in Sturtevant's benchmarks (IEEE TCIAIG 4(2), 2012). The
//! heuristic is the octile distance, which is admissible and consistent for these moves, so
//! the first time the goal is taken from the open list its cost is optimal.
//!
//! Ties between equal f = g + h are broken toward the larger g (deeper nodes first, fewer
//! expansions), then the smaller cell index, so the path returned is deterministic.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A path of cells (column, row) from start to goal inclusive, and its length in cells.
#[derive(Debug, Clone, PartialEq)]
pub struct GridPath {
    /// Cells (column, row), start first.
    pub cells: Vec<(usize, usize)>,
    /// Sum of move costs: 1 per straight move, √2 per diagonal move.
    pub length: f64,
}

/// An entry of the open list.
#[derive(Debug, Clone, Copy)]
struct Open {
    f: f64,
    g: f64,
    cell: usize,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Open {
    /// `BinaryHeap` is a max-heap: the "greatest" entry is the smallest f, then largest g,
    /// then smallest cell index.
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .f
            .total_cmp(&self.f)
            .then(self.g.total_cmp(&other.g))
            .then(other.cell.cmp(&self.cell))
    }
}

/// Octile distance between two cells.
fn octile(a: (usize, usize), b: (usize, usize)) -> f64 {
    let dx = a.0.abs_diff(b.0) as f64;
    let dy = a.1.abs_diff(b.1) as f64;
    let (lo, hi) = if dx < dy { (dx, dy) } else { (dy, dx) };
    hi + (std::f64::consts::SQRT_2 - 1.0) * lo
}

/// The shortest path from `start` to `goal` (cells as (column, row)) on a grid of `rows` ×
/// `cols` cells where `blocked[row * cols + col]` marks cells that cannot be entered; `None`
/// when the goal cannot be reached or either end is blocked or outside the grid.
pub fn shortest_path(
    blocked: &[bool],
    rows: usize,
    cols: usize,
    start: (usize, usize),
    goal: (usize, usize),
) -> Option<GridPath> {
    PathSearch::new(blocked, rows, cols).shortest_path(start, goal)
}

/// A* over one grid, keeping its work arrays between searches: each search then costs what it
/// expands, not the size of the map (the route planner and the benchmarks search many times).
pub struct PathSearch<'a> {
    blocked: &'a [bool],
    rows: usize,
    cols: usize,
    /// Per-cell search state, one record per cell so that a relaxation touches one cache line.
    nodes: Vec<Node>,
    /// Number of the current search; a node is valid only when stamped with it.
    current: u32,
    open: BinaryHeap<Open>,
}

/// What a search knows of one cell.
#[derive(Debug, Clone, Copy)]
struct Node {
    /// Search number that last touched the cell.
    stamp: u32,
    /// Predecessor on the best path found, `u32::MAX` for none.
    parent: u32,
    /// Cost of the best path found.
    g: f64,
    /// Whether the cell has been expanded.
    closed: bool,
}

const UNTOUCHED: Node = Node {
    stamp: 0,
    parent: u32::MAX,
    g: f64::INFINITY,
    closed: false,
};

impl<'a> PathSearch<'a> {
    /// A search context for `blocked` (`rows` × `cols`, row-major).
    pub fn new(blocked: &'a [bool], rows: usize, cols: usize) -> Self {
        Self {
            blocked,
            rows,
            cols,
            nodes: vec![UNTOUCHED; rows * cols],
            current: 0,
            open: BinaryHeap::new(),
        }
    }

    /// The state of `cell` in the current search, reset if an earlier search left it.
    #[inline]
    fn node(&mut self, cell: usize) -> &mut Node {
        let current = self.current;
        let node = &mut self.nodes[cell];
        if node.stamp != current {
            *node = Node {
                stamp: current,
                ..UNTOUCHED
            };
        }
        node
    }

    /// The shortest path from `start` to `goal`, as [`shortest_path`].
    pub fn shortest_path(
        &mut self,
        start: (usize, usize),
        goal: (usize, usize),
    ) -> Option<GridPath> {
        let (rows, cols) = (self.rows, self.cols);
        let inside = |(c, r): (usize, usize)| c < cols && r < rows;
        if !inside(start) || !inside(goal) {
            return None;
        }
        let index = |(c, r): (usize, usize)| r * cols + c;
        if self.blocked[index(start)] || self.blocked[index(goal)] {
            return None;
        }
        self.current = self.current.wrapping_add(1);
        if self.current == 0 {
            // After 2³² searches the stamps wrap: clear them once.
            self.nodes.fill(UNTOUCHED);
            self.current = 1;
        }
        self.open.clear();
        let s = index(start);
        self.node(s).g = 0.0;
        self.open.push(Open {
            f: octile(start, goal),
            g: 0.0,
            cell: s,
        });
        let goal_index = index(goal);
        while let Some(Open {
            g: g_here, cell, ..
        }) = self.open.pop()
        {
            let node = self.node(cell);
            if node.closed {
                continue;
            }
            node.closed = true;
            if cell == goal_index {
                return Some(self.reconstruct(cell, g_here));
            }
            self.expand(cell, g_here, goal);
        }
        None
    }

    /// The path to `goal` by following parents back to the start.
    fn reconstruct(&self, goal: usize, length: f64) -> GridPath {
        let cols = self.cols;
        let mut cells = vec![(goal % cols, goal / cols)];
        let mut at = goal;
        while self.nodes[at].parent != u32::MAX {
            at = self.nodes[at].parent as usize;
            cells.push((at % cols, at / cols));
        }
        cells.reverse();
        GridPath { cells, length }
    }

    /// Relax the moves out of `cell`.
    fn expand(&mut self, cell: usize, g_here: f64, goal: (usize, usize)) {
        let (rows, cols) = (self.rows, self.cols);
        let (c, r) = ((cell % cols) as isize, (cell / cols) as isize);
        for (dc, dr) in [
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
        ] {
            let (nc, nr) = (c + dc, r + dr);
            if nc < 0 || nr < 0 || nc >= cols as isize || nr >= rows as isize {
                continue;
            }
            let next = nr as usize * cols + nc as usize;
            if self.blocked[next] {
                continue;
            }
            let diagonal = dc != 0 && dr != 0;
            if diagonal {
                // No corner cutting: both cells beside the diagonal must be free.
                let side_a = r as usize * cols + nc as usize;
                let side_b = nr as usize * cols + c as usize;
                if self.blocked[side_a] || self.blocked[side_b] {
                    continue;
                }
            }
            let step = if diagonal {
                std::f64::consts::SQRT_2
            } else {
                1.0
            };
            let candidate = g_here + step;
            let node = self.node(next);
            if !node.closed && candidate < node.g {
                node.g = candidate;
                node.parent = cell as u32;
                self.open.push(Open {
                    f: candidate + octile((nc as usize, nr as usize), goal),
                    g: candidate,
                    cell: next,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: &[&str]) -> (Vec<bool>, usize, usize) {
        let cells = rows
            .iter()
            .flat_map(|r| r.chars().map(|ch| ch == '@'))
            .collect();
        (cells, rows.len(), rows[0].len())
    }

    #[test]
    fn open_ground_gives_the_octile_distance() {
        let (b, rows, cols) = grid(&["....", "....", "...."]);
        let p = shortest_path(&b, rows, cols, (0, 0), (3, 2)).unwrap();
        assert!((p.length - (1.0 + 2.0 * std::f64::consts::SQRT_2)).abs() < 1e-12);
        assert_eq!(p.cells.first(), Some(&(0, 0)));
        assert_eq!(p.cells.last(), Some(&(3, 2)));
    }

    #[test]
    fn corners_are_not_cut() {
        let (b, rows, cols) = grid(&[".@", ".."]);
        let p = shortest_path(&b, rows, cols, (0, 0), (1, 1)).unwrap();
        assert_eq!(p.length, 2.0);
        let (b, rows, cols) = grid(&[".@", "@."]);
        assert!(shortest_path(&b, rows, cols, (0, 0), (1, 1)).is_none());
    }

    #[test]
    fn blocked_or_outside_ends_have_no_path() {
        let (b, rows, cols) = grid(&[".@"]);
        assert!(shortest_path(&b, rows, cols, (0, 0), (1, 0)).is_none());
        assert!(shortest_path(&b, rows, cols, (0, 0), (5, 0)).is_none());
        assert_eq!(
            shortest_path(&b, rows, cols, (0, 0), (0, 0))
                .unwrap()
                .length,
            0.0
        );
    }
}
