//! MovingAI grid maps (`.map`) and scenarios (`.scen`).
//!
//! Format (Sturtevant, "Benchmarks for Grid-Based Pathfinding", IEEE TCIAIG 4(2), 2012, and the
//! benchmark's own loader): a header `type octile`, `height H`, `width W`, `map`, then H lines of
//! W characters, row 0 at the top. `.`, `G` and `S` are passable; every other character
//! (`@`, `O`, `T`, `W`) is blocked; any other character is an error. Lines may end in CRLF. A scenario file starts `version 1`
//! and lists one problem per line, tab-separated: bucket, map, width, height, start x, start y,
//! goal x, goal y, optimal length (x = column, y = row).

use crate::grid::OccupancyGrid;

/// One MovingAI problem.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// Start cell (column, row).
    pub start: (usize, usize),
    /// Goal cell (column, row).
    pub goal: (usize, usize),
    /// Optimal path length as printed in the file.
    pub optimal: f64,
}

/// Parse a `.map` file's text into an occupancy grid (blocked = occupied).
pub fn parse_map(text: &str) -> Result<OccupancyGrid, String> {
    let mut lines = text.lines().map(|l| l.trim_end_matches('\r'));
    let mut height = None;
    let mut width = None;
    for line in lines.by_ref() {
        let mut words = line.split_whitespace();
        match (words.next(), words.next()) {
            (Some("type"), _) => {}
            (Some("height"), Some(h)) => height = h.parse::<usize>().ok(),
            (Some("width"), Some(w)) => width = w.parse::<usize>().ok(),
            (Some("map"), None) => break,
            (None, _) => {}
            _ => return Err(format!("unexpected header line `{line}`")),
        }
    }
    let (Some(rows), Some(cols)) = (height, width) else {
        return Err("the header must give `height` and `width` before `map`".into());
    };
    crate::grid::check_size(rows, cols)?;
    let mut grid = OccupancyGrid::filled(rows, cols, true);
    let mut read = 0;
    for (r, line) in lines.take(rows).enumerate() {
        if line.chars().count() != cols {
            return Err(format!(
                "map row {r} has {} characters, expected {cols}",
                line.chars().count()
            ));
        }
        for (c, ch) in line.chars().enumerate() {
            let blocked = match ch {
                '.' | 'G' | 'S' => false,
                '@' | 'O' | 'T' | 'W' => true,
                // A character the benchmark does not define is more likely a damaged or
                // foreign file than an obstacle.
                other => {
                    return Err(format!(
                        "map row {r}, column {c}: unknown character {other:?}; expected one of \
                         . G S (passable) or @ O T W (blocked)"
                    ))
                }
            };
            grid.set(r, c, blocked);
        }
        read += 1;
    }
    if read != rows {
        return Err(format!("the map has {read} rows, expected {rows}"));
    }
    Ok(grid)
}

/// Parse a `.scen` file's text.
pub fn parse_scenarios(text: &str) -> Result<Vec<Problem>, String> {
    let mut problems = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim_end_matches('\r');
        if n == 0 && line.starts_with("version") || line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split('\t').collect();
        if fields.len() != 9 {
            return Err(format!("line {}: expected 9 tab-separated fields", n + 1));
        }
        let num = |i: usize| -> Result<usize, String> {
            fields[i]
                .trim()
                .parse()
                .map_err(|_| format!("line {}: field {} is not a cell index", n + 1, i + 1))
        };
        problems.push(Problem {
            start: (num(4)?, num(5)?),
            goal: (num(6)?, num(7)?),
            optimal: fields[8]
                .trim()
                .parse()
                .map_err(|_| format!("line {}: the optimal length is not a number", n + 1))?,
        });
    }
    Ok(problems)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crlf_maps_parse_and_only_ground_is_free() {
        let text = "type octile\r\nheight 2\r\nwidth 3\r\nmap\r\n.@T\r\nGS.\r\n";
        let g = parse_map(text).unwrap();
        assert_eq!((g.rows, g.cols), (2, 3));
        assert_eq!(g.cells, vec![false, true, true, false, false, false]);
    }

    #[test]
    fn a_header_too_large_is_refused_before_allocating() {
        let e = parse_map("type octile\nheight 1000000000\nwidth 1000000000\nmap\n").unwrap_err();
        assert!(e.contains("more than the 100000000"), "{e}");
        let e = parse_map("type octile\nheight 0\nwidth 5\nmap\n").unwrap_err();
        assert!(e.contains("empty map"), "{e}");
    }

    #[test]
    fn a_character_the_benchmark_does_not_define_is_an_error() {
        let e = parse_map("type octile\nheight 1\nwidth 3\nmap\n.#.\n").unwrap_err();
        assert_eq!(
            e,
            "map row 0, column 1: unknown character '#'; expected one of . G S (passable) or \
             @ O T W (blocked)"
        );
        assert!(parse_map("type octile\nheight 1\nwidth 4\nmap\n@OTW\n").is_ok());
    }

    #[test]
    fn short_rows_are_errors() {
        let e = parse_map("type octile\nheight 2\nwidth 3\nmap\n...\n..\n").unwrap_err();
        assert_eq!(e, "map row 1 has 2 characters, expected 3");
    }
}
