//! STL's space robustness over discrete-time signals, offline, as rtamt's discrete-time
//! offline monitor defines it (rtamt 0.4.10, `StlDiscreteTimeOfflineAstVisitor`): every
//! operator maps whole signals to a signal, and a requirement's robustness is its value at
//! sample 0.
//!
//! Per operator, for samples 0..n and a window [a, b] in samples:
//! - comparisons: `x < c` and `x <= c` give c − x, `>` and `>=` give x − c, `==` gives −|x − c|,
//!   `!==` gives |x − c|; `not` negates; `and`/`or` are min/max; `implies` is max(−φ, ψ);
//!   `iff` −|φ − ψ|; `xor` |φ − ψ|;
//! - `always[a:b] φ` at i is the min of φ over [i+a, i+b] cut at the trace's end (+∞ when the
//!   window lies past it); `eventually` the max (−∞ past the end); untimed, the whole suffix;
//! - `historically[a:b] φ` and `once[a:b] φ` look back over [i−b, i−a] cut at 0;
//! - `φ until[a:b] ψ` at i is max over d in [a, b], i+d < n, of min(ψ(i+d), min φ over
//!   [i, i+d)); `φ since[a:b] ψ` the same backwards (φ over (i−d, i]);
//! - `prev` reads +∞ at sample 0 and `next` +∞ at the last (`s_prev`, `s_next`: −∞);
//!   `rise(φ)` is min(−φ(i−1), φ(i)) with φ(−1) = −∞, `fall(φ)` min(φ(i−1), −φ(i)) with +∞.
//!
//! Windowed min/max run in O(n) with a monotonic deque (Lemire's streaming algorithm); a timed
//! `until`/`since` in O(n·b) at worst, cut short once the running min of φ can no longer beat
//! the best so far. Code is postfix ([`super::parse`]); buffers are reused, so a long formula
//! needs as many as its deepest nesting.

use std::collections::VecDeque;

/// A window `[begin, end]`, in samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First sample offset.
    pub begin: usize,
    /// Last sample offset.
    pub end: usize,
}

/// A comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cmp {
    /// `<`
    Less,
    /// `<=`
    LessEq,
    /// `>`
    Greater,
    /// `>=`
    GreaterEq,
    /// `==`
    Eq,
    /// `!==`
    NotEq,
}

/// One instruction of postfix code.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Instr {
    /// Push signal `i`.
    Signal(usize),
    /// Push a constant.
    Const(f64),
    /// Negate (`not`, unary minus).
    Not,
    /// `abs`.
    Abs,
    /// `sqrt`.
    Sqrt,
    /// `exp`.
    Exp,
    /// `pow(x, y)`.
    Pow,
    /// `+`.
    Add,
    /// `-`.
    Sub,
    /// `*`.
    Mul,
    /// `/`.
    Div,
    /// A comparison.
    Cmp(Cmp),
    /// `and`.
    And,
    /// `or`.
    Or,
    /// `implies`.
    Implies,
    /// `iff`.
    Iff,
    /// `xor`.
    Xor,
    /// `always`, optionally bounded.
    Always(Option<Window>),
    /// `eventually`.
    Eventually(Option<Window>),
    /// `historically`.
    Historically(Option<Window>),
    /// `once`.
    Once(Option<Window>),
    /// `prev`.
    Prev,
    /// `next`.
    Next,
    /// `s_prev`.
    StrongPrev,
    /// `s_next`.
    StrongNext,
    /// `rise`.
    Rise,
    /// `fall`.
    Fall,
    /// `until`.
    Until(Option<Window>),
    /// `since`.
    Since(Option<Window>),
}

impl Instr {
    /// How many operands it takes off the stack.
    pub fn arity(&self) -> usize {
        match self {
            Instr::Signal(_) | Instr::Const(_) => 0,
            Instr::Pow
            | Instr::Add
            | Instr::Sub
            | Instr::Mul
            | Instr::Div
            | Instr::Cmp(_)
            | Instr::And
            | Instr::Or
            | Instr::Implies
            | Instr::Iff
            | Instr::Xor
            | Instr::Until(_)
            | Instr::Since(_) => 2,
            _ => 1,
        }
    }
}

/// The robustness signal of `code` over `signals` (each of `n` samples), and of the top
/// instruction's first operand (for explaining a violation).
pub fn evaluate(code: &[Instr], signals: &[&[f64]], n: usize) -> (Vec<f64>, Option<Vec<f64>>) {
    let mut stack: Vec<Vec<f64>> = Vec::new();
    let mut spare: Vec<Vec<f64>> = Vec::new();
    let mut operand = None;
    for (k, instr) in code.iter().enumerate() {
        let last = k + 1 == code.len();
        if last && instr.arity() > 0 {
            operand = Some(stack[stack.len() - instr.arity()].clone());
        }
        let mut fresh = || {
            let mut v = spare.pop().unwrap_or_default();
            v.clear();
            v
        };
        match *instr {
            Instr::Signal(i) => {
                let mut v = fresh();
                v.extend_from_slice(&signals[i][..n]);
                stack.push(v);
            }
            Instr::Const(c) => {
                let mut v = fresh();
                v.resize(n, c);
                stack.push(v);
            }
            Instr::Not => map(&mut stack, |x| -x),
            Instr::Abs => map(&mut stack, f64::abs),
            Instr::Sqrt => map(&mut stack, f64::sqrt),
            Instr::Exp => map(&mut stack, f64::exp),
            Instr::Pow => zip(&mut stack, &mut spare, f64::powf),
            Instr::Add => zip(&mut stack, &mut spare, |l, r| l + r),
            Instr::Sub => zip(&mut stack, &mut spare, |l, r| l - r),
            Instr::Mul => zip(&mut stack, &mut spare, |l, r| l * r),
            Instr::Div => zip(&mut stack, &mut spare, |l, r| l / r),
            Instr::Cmp(c) => zip(&mut stack, &mut spare, move |l, r| match c {
                Cmp::Less | Cmp::LessEq => r - l,
                Cmp::Greater | Cmp::GreaterEq => l - r,
                Cmp::Eq => -(l - r).abs(),
                Cmp::NotEq => (l - r).abs(),
            }),
            Instr::And => zip(&mut stack, &mut spare, min),
            Instr::Or => zip(&mut stack, &mut spare, max),
            Instr::Implies => zip(&mut stack, &mut spare, |l, r| max(-l, r)),
            Instr::Iff => zip(&mut stack, &mut spare, |l, r| -(l - r).abs()),
            Instr::Xor => zip(&mut stack, &mut spare, |l, r| (l - r).abs()),
            Instr::Always(w) => temporal(&mut stack, w, true, true),
            Instr::Eventually(w) => temporal(&mut stack, w, true, false),
            Instr::Historically(w) => temporal(&mut stack, w, false, true),
            Instr::Once(w) => temporal(&mut stack, w, false, false),
            Instr::Prev | Instr::StrongPrev => {
                let fill = if *instr == Instr::Prev {
                    f64::INFINITY
                } else {
                    f64::NEG_INFINITY
                };
                let top = stack.last_mut().expect("an operand");
                if !top.is_empty() {
                    top.pop();
                    top.insert(0, fill);
                }
            }
            Instr::Next | Instr::StrongNext => {
                let fill = if *instr == Instr::Next {
                    f64::INFINITY
                } else {
                    f64::NEG_INFINITY
                };
                let top = stack.last_mut().expect("an operand");
                if !top.is_empty() {
                    top.remove(0);
                    top.push(fill);
                }
            }
            Instr::Rise | Instr::Fall => {
                let rise = *instr == Instr::Rise;
                let top = stack.last_mut().expect("an operand");
                let mut before = if rise {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                };
                for x in top.iter_mut() {
                    let now = *x;
                    *x = if rise {
                        min(-before, now)
                    } else {
                        min(before, -now)
                    };
                    before = now;
                }
            }
            Instr::Until(w) => {
                let rhs = stack.pop().expect("two operands");
                let lhs = stack.last_mut().expect("two operands");
                match w {
                    None => until(lhs, &rhs),
                    Some(w) => *lhs = until_within(lhs, &rhs, w, false),
                }
                spare.push(rhs);
            }
            Instr::Since(w) => {
                let rhs = stack.pop().expect("two operands");
                let lhs = stack.last_mut().expect("two operands");
                match w {
                    None => since(lhs, &rhs),
                    Some(w) => *lhs = until_within(lhs, &rhs, w, true),
                }
                spare.push(rhs);
            }
        }
    }
    (stack.pop().expect("code leaves one signal"), operand)
}

/// min as rtamt's Python `min(a, b)` takes it: a unless b is smaller.
fn min(a: f64, b: f64) -> f64 {
    if b < a {
        b
    } else {
        a
    }
}

/// max as Python's `max(a, b)`: a unless b is larger.
fn max(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

fn map(stack: &mut [Vec<f64>], f: impl Fn(f64) -> f64) {
    for x in stack.last_mut().expect("an operand").iter_mut() {
        *x = f(*x);
    }
}

fn zip(stack: &mut Vec<Vec<f64>>, spare: &mut Vec<Vec<f64>>, f: impl Fn(f64, f64) -> f64) {
    let rhs = stack.pop().expect("two operands");
    let lhs = stack.last_mut().expect("two operands");
    for (l, r) in lhs.iter_mut().zip(&rhs) {
        *l = f(*l, *r);
    }
    spare.push(rhs);
}

/// `always` (`future`, `minimum`), `eventually` (`future`), `historically` (`minimum`) or
/// `once` over the top of the stack, in place, bounded by `w` or not.
fn temporal(stack: &mut [Vec<f64>], w: Option<Window>, future: bool, minimum: bool) {
    let top = stack.last_mut().expect("an operand");
    let (init, op): (f64, fn(f64, f64) -> f64) = if minimum {
        (f64::INFINITY, min)
    } else {
        (f64::NEG_INFINITY, max)
    };
    match (w, future) {
        (None, true) => suffix(top, init, op),
        (None, false) => prefix(top, init, op),
        (Some(w), true) => *top = ahead(top, w, minimum),
        (Some(w), false) => *top = behind(top, w, minimum),
    }
}

/// Untimed future operator: each sample becomes `op` over itself and everything after.
fn suffix(x: &mut [f64], init: f64, op: fn(f64, f64) -> f64) {
    let mut acc = init;
    for v in x.iter_mut().rev() {
        acc = op(*v, acc);
        *v = acc;
    }
}

/// Untimed past operator: each sample becomes `op` over itself and everything before.
fn prefix(x: &mut [f64], init: f64, op: fn(f64, f64) -> f64) {
    let mut acc = init;
    for v in x.iter_mut() {
        acc = op(*v, acc);
        *v = acc;
    }
}

/// `always[a:b]` (`minimum`) or `eventually[a:b]` at every sample: the min (max) of x over
/// [i+a, i+b] cut at the end, ±∞ past it. A monotonic deque of candidates, right to left.
fn ahead(x: &[f64], w: Window, minimum: bool) -> Vec<f64> {
    let n = x.len();
    let empty = if minimum {
        f64::INFINITY
    } else {
        f64::NEG_INFINITY
    };
    let better = |a: f64, b: f64| if minimum { a <= b } else { a >= b };
    let span = w.end - w.begin;
    // best[j]: min (max) of x over [j, j + span], for j from the end down.
    let mut best = vec![empty; n];
    let mut deque: VecDeque<usize> = VecDeque::new();
    for j in (0..n).rev() {
        while deque.back().is_some_and(|&k| better(x[j], x[k])) {
            deque.pop_back();
        }
        deque.push_back(j);
        while deque.front().is_some_and(|&k| k > j + span) {
            deque.pop_front();
        }
        best[j] = x[*deque.front().expect("j was pushed")];
    }
    (0..n)
        .map(|i| best.get(i + w.begin).copied().unwrap_or(empty))
        .collect()
}

/// `historically[a:b]` or `once[a:b]`: the min (max) over [i−b, i−a] cut at 0.
fn behind(x: &[f64], w: Window, minimum: bool) -> Vec<f64> {
    let mut reversed: Vec<f64> = x.iter().rev().copied().collect();
    reversed = ahead(&reversed, w, minimum);
    reversed.reverse();
    reversed
}

/// Untimed `until`, in place in `lhs`: max(ψ(i), min(φ(i), out(i+1))), out(n) = −∞.
fn until(lhs: &mut [f64], rhs: &[f64]) {
    let mut next = f64::NEG_INFINITY;
    for i in (0..lhs.len()).rev() {
        next = max(min(lhs[i], next), rhs[i]);
        lhs[i] = next;
    }
}

/// Untimed `since`, in place: max(ψ(i), min(φ(i), out(i−1))), out(−1) = −∞.
fn since(lhs: &mut [f64], rhs: &[f64]) {
    let mut before = f64::NEG_INFINITY;
    for i in 0..lhs.len() {
        before = max(min(lhs[i], before), rhs[i]);
        lhs[i] = before;
    }
}

/// Timed `until` (or, `backward`, `since`) at every sample.
fn until_within(lhs: &[f64], rhs: &[f64], w: Window, backward: bool) -> Vec<f64> {
    let n = lhs.len() as isize;
    let step: isize = if backward { -1 } else { 1 };
    (0..n)
        .map(|i| {
            let mut best = f64::NEG_INFINITY;
            // min of φ over the samples strictly between i and i ± d (inclusive of i)
            let mut held = f64::INFINITY;
            for d in 0..=w.end as isize {
                let j = i + step * d;
                if j < 0 || j >= n {
                    break;
                }
                let j = j as usize;
                if d as usize >= w.begin {
                    best = max(best, min(rhs[j], held));
                }
                held = min(held, lhs[j]);
                if held <= best {
                    break;
                }
            }
            best
        })
        .collect()
}
