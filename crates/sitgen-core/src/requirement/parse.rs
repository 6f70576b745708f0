//! Reading a requirement: rtamt's STL grammar (rtamt 0.4.10, `StlParser.g4` and
//! `LtlLexer.g4`) turned into code for the robustness machine ([`super::robustness`]).
//!
//! The grammar is ANTLR's: one alternative a precedence level, the first binding tightest,
//! every binary operator left-associative. From tightest to loosest: parentheses, `abs`
//! `sqrt` `exp` `pow` `rise` `fall`, negation, `*` `/`, `+` `-`, comparisons, `not`, the
//! prefix temporal operators (`always`, `eventually`, `historically`, `once`, `prev`, `next`,
//! `s_prev`, `s_next`), `until`, `unless`, `since`, `and`, `or`, `implies`, `iff`, `xor`. The
//! lexer is ANTLR's too: the longest token wins, a keyword wins over a name of the same length,
//! and a name may hold `.` and `/` (so `a/b` is one name, as rtamt reads it).
//!
//! Two places where rtamt's releases read a formula differently are refused rather than read
//! one way: `a / b * c` and `a - b + c` (rtamt 0.4.10 gives `*` and `+` their own, tighter
//! level; later releases read them left to right). Unary minus on an expression (`-speed`) is
//! read as later releases do; 0.4.10 takes it only before a number.
//!
//! The parser emits postfix code directly (a Pratt parser), so a formula thousands of
//! operators long needs no tree and no deep recursion; nesting (parentheses, prefix operators)
//! is limited to [`MAX_DEPTH`].

use super::robustness::{Cmp, Instr, Window};

/// Deepest nesting of parentheses and prefix operators a formula may have.
pub const MAX_DEPTH: usize = 200;
/// Most tokens a formula may have.
pub const MAX_TOKENS: usize = 100_000;

/// A formula that does not read: the 1-based column (in characters) and what was expected.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// 1-based column, in characters.
    pub column: usize,
    /// What was wrong and what was expected there.
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Kw(&'static str),
    Sym(&'static str),
    End,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::Num(v) => format!("the number {v}"),
            Tok::Name(n) => format!("'{n}'"),
            Tok::Kw(k) | Tok::Sym(k) => format!("'{k}'"),
            Tok::End => "the end of the formula".into(),
        }
    }
}

/// Keywords, each as rtamt spells it, with the canonical word it stands for.
const KEYWORDS: [(&str, &str); 48] = [
    ("abs", "abs"),
    ("sqrt", "sqrt"),
    ("exp", "exp"),
    ("pow", "pow"),
    ("s", "s"),
    ("ms", "ms"),
    ("us", "us"),
    ("ns", "ns"),
    ("ps", "ps"),
    ("not", "not"),
    ("or", "or"),
    ("and", "and"),
    ("iff", "iff"),
    ("implies", "implies"),
    ("xor", "xor"),
    ("rise", "rise"),
    ("fall", "fall"),
    ("always", "always"),
    ("G", "always"),
    ("eventually", "eventually"),
    ("F", "eventually"),
    ("until", "until"),
    ("U", "until"),
    ("unless", "unless"),
    ("W", "unless"),
    ("historically", "historically"),
    ("H", "historically"),
    ("once", "once"),
    ("O", "once"),
    ("since", "since"),
    ("S", "since"),
    ("next", "next"),
    ("X", "next"),
    ("prev", "prev"),
    ("Y", "prev"),
    ("s_next", "s_next"),
    ("sX", "s_next"),
    ("s_prev", "s_prev"),
    ("sY", "s_prev"),
    ("true", "true"),
    ("TRUE", "true"),
    ("false", "false"),
    ("FALSE", "false"),
    ("const", "const"),
    ("input", "input"),
    ("output", "output"),
    ("float", "float"),
    ("int", "int"),
];

/// Symbols, longest first so that the longest match wins.
const SYMBOLS: [(&str, &str); 20] = [
    ("!==", "!=="),
    ("<->", "iff"),
    ("==", "=="),
    (">=", ">="),
    ("<=", "<="),
    ("->", "implies"),
    (">", ">"),
    ("<", "<"),
    ("=", "="),
    ("!", "not"),
    ("|", "or"),
    ("&", "and"),
    ("(", "("),
    (")", ")"),
    ("[", "["),
    ("]", "]"),
    (":", ":"),
    (",", ","),
    ("+", "+"),
    ("*", "*"),
];

fn lex(text: &str) -> Result<Vec<(Tok, usize)>, ParseError> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    let name_start = |c: char| c.is_ascii_alphabetic() || c == '_' || c == '$';
    let name_part = |c: char| name_start(c) || c.is_ascii_digit() || c == '.' || c == '/';
    while i < chars.len() {
        let c = chars[i];
        let column = i + 1;
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        if out.len() >= MAX_TOKENS {
            return Err(ParseError {
                column,
                message: format!("the formula has more than {MAX_TOKENS} tokens"),
            });
        }
        if name_start(c) {
            let start = i;
            while i < chars.len() && name_part(chars[i]) {
                i += 1;
            }
            let word: String = chars[start..i].iter().collect();
            let tok = match KEYWORDS.iter().find(|(k, _)| *k == word) {
                Some((_, canonical)) => Tok::Kw(canonical),
                None => Tok::Name(word),
            };
            out.push((tok, column));
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && chars.get(i + 1).is_some_and(char::is_ascii_digit)) {
            let (value, end) = number(&chars, i).ok_or_else(|| ParseError {
                column,
                message: "expected a number".into(),
            })?;
            i = end;
            out.push((Tok::Num(value), column));
            continue;
        }
        if c == '-' {
            let arrow = chars.get(i + 1) == Some(&'>');
            out.push((Tok::Sym(if arrow { "implies" } else { "-" }), column));
            i += if arrow { 2 } else { 1 };
            continue;
        }
        if c == '/' {
            out.push((Tok::Sym("/"), column));
            i += 1;
            continue;
        }
        let rest: String = chars[i..chars.len().min(i + 3)].iter().collect();
        match SYMBOLS.iter().find(|(s, _)| rest.starts_with(s)) {
            Some((s, canonical)) => {
                out.push((Tok::Sym(canonical), column));
                i += s.chars().count();
            }
            None => {
                return Err(ParseError {
                    column,
                    message: format!("'{c}' is not part of rtamt's STL syntax"),
                })
            }
        }
    }
    out.push((Tok::End, chars.len() + 1));
    Ok(out)
}

/// A numeric literal at `i`: decimal (underscores allowed between digits), `0x` hex, `0b`
/// binary, or real (`1.`, `.5`, `2.5e-3`, `1e3`). Returns the value and the index after it.
fn number(chars: &[char], i: usize) -> Option<(f64, usize)> {
    let at = |k: usize| chars.get(k).copied().unwrap_or('\0');
    if at(i) == '0' && matches!(at(i + 1), 'x' | 'X' | 'b' | 'B') {
        let radix = if matches!(at(i + 1), 'x' | 'X') {
            16
        } else {
            2
        };
        let mut k = i + 2;
        let mut digits = String::new();
        while at(k).is_digit(radix) || at(k) == '_' {
            if at(k) != '_' {
                digits.push(at(k));
            }
            k += 1;
        }
        return u64::from_str_radix(&digits, radix)
            .ok()
            .map(|v| (v as f64, k));
    }
    let mut k = i;
    let mut text = String::new();
    let digits = |k: &mut usize, text: &mut String| {
        while at(*k).is_ascii_digit() || (at(*k) == '_' && at(*k + 1).is_ascii_digit()) {
            if at(*k) != '_' {
                text.push(at(*k));
            }
            *k += 1;
        }
    };
    digits(&mut k, &mut text);
    if at(k) == '.' {
        text.push('.');
        k += 1;
        digits(&mut k, &mut text);
    }
    if matches!(at(k), 'e' | 'E') {
        let sign = matches!(at(k + 1), '+' | '-');
        if at(k + 1 + usize::from(sign)).is_ascii_digit() {
            text.push('e');
            if sign {
                text.push(at(k + 1));
            }
            k += 1 + usize::from(sign);
            while at(k).is_ascii_digit() {
                text.push(at(k));
                k += 1;
            }
        }
    }
    text.parse::<f64>().ok().map(|v| (v, k))
}

/// Binding power of a binary operator (higher binds tighter), its rtamt level.
fn binary_power(tok: &Tok) -> Option<u8> {
    let name = match tok {
        Tok::Sym(s) | Tok::Kw(s) => *s,
        _ => return None,
    };
    Some(match name {
        "*" | "/" => 20,
        "+" | "-" => 19,
        "<" | "<=" | ">" | ">=" | "==" | "!==" => 18,
        "until" => 15,
        "unless" => 14,
        "since" => 13,
        "and" => 12,
        "or" => 11,
        "implies" => 10,
        "iff" => 9,
        "xor" => 8,
        _ => return None,
    })
}

/// The operand of `not` and the prefix temporal operators takes arithmetic and comparisons
/// (the levels above theirs) and stops at `until` and everything looser.
const PREFIX_OPERAND: u8 = 18;
/// The operand of unary minus is a primary.
const NEGATION_OPERAND: u8 = 21;

struct Parser<'a> {
    toks: Vec<(Tok, usize)>,
    at: usize,
    code: Vec<Instr>,
    depth: usize,
    signal: &'a dyn Fn(&str) -> Option<usize>,
    /// Every signal's name, for the message about one that is not.
    known: &'a [&'a str],
    dt_s: f64,
}

/// Compile `text` to postfix code; `signal` maps a name to its index, `known` lists the
/// names, `dt_s` is the sampling period bounds are counted in.
pub fn compile(
    text: &str,
    signal: &dyn Fn(&str) -> Option<usize>,
    known: &[&str],
    dt_s: f64,
) -> Result<Vec<Instr>, ParseError> {
    let toks = lex(text)?;
    let mut p = Parser {
        toks,
        at: 0,
        code: Vec::new(),
        depth: 0,
        signal,
        known,
        dt_s,
    };
    p.expression(0)?;
    match p.peek() {
        Tok::End => Ok(p.code),
        t => Err(p.error(format!(
            "expected an operator or the end of the formula, found {}",
            t.describe()
        ))),
    }
}

impl Parser<'_> {
    fn peek(&self) -> &Tok {
        &self.toks[self.at].0
    }

    fn column(&self) -> usize {
        self.toks[self.at].1
    }

    fn error(&self, message: String) -> ParseError {
        ParseError {
            column: self.column(),
            message,
        }
    }

    fn next(&mut self) -> Tok {
        let t = self.toks[self.at].0.clone();
        if self.at + 1 < self.toks.len() {
            self.at += 1;
        }
        t
    }

    fn expect(&mut self, sym: &str) -> Result<(), ParseError> {
        match self.peek() {
            Tok::Sym(s) if *s == sym => {
                self.next();
                Ok(())
            }
            t => Err(self.error(format!("expected '{sym}', found {}", t.describe()))),
        }
    }

    /// An expression whose binary operators all bind at least `min_power`.
    fn expression(&mut self, min_power: u8) -> Result<(), ParseError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.error(format!(
                "the formula nests deeper than {MAX_DEPTH} levels (parentheses and prefix operators)"
            )));
        }
        self.prefix()?;
        // The last multiplicative and additive operator of this chain, for the two mixtures
        // rtamt's releases read differently.
        let mut last: Option<&'static str> = None;
        loop {
            let tok = self.peek().clone();
            let Some(power) = binary_power(&tok) else {
                break;
            };
            if power < min_power {
                break;
            }
            let (Tok::Sym(op) | Tok::Kw(op)) = tok else {
                unreachable!("binary operators are symbols or keywords")
            };
            if (last == Some("/") && op == "*") || (last == Some("-") && op == "+") {
                return Err(self.error(format!(
                    "write ( ) around '{} {op}': rtamt's releases read 'a {} b {op} c' differently",
                    last.unwrap_or_default(),
                    last.unwrap_or_default()
                )));
            }
            if power >= 19 {
                last = Some(op);
            }
            self.next();
            let window = if matches!(op, "until" | "unless" | "since") {
                self.window()?
            } else {
                None
            };
            // Only `unless` copies its left operand; finding it walks back over the code.
            let lhs_start = if op == "unless" {
                start_of_last(&self.code)
            } else {
                0
            };
            self.expression(power + 1)?;
            self.binary(op, window, lhs_start)?;
        }
        self.depth -= 1;
        Ok(())
    }

    fn binary(
        &mut self,
        op: &str,
        window: Option<Window>,
        lhs_start: usize,
    ) -> Result<(), ParseError> {
        let instr = match op {
            "*" => Instr::Mul,
            "/" => Instr::Div,
            "+" => Instr::Add,
            "-" => Instr::Sub,
            "<" => Instr::Cmp(Cmp::Less),
            "<=" => Instr::Cmp(Cmp::LessEq),
            ">" => Instr::Cmp(Cmp::Greater),
            ">=" => Instr::Cmp(Cmp::GreaterEq),
            "==" => Instr::Cmp(Cmp::Eq),
            "!==" => Instr::Cmp(Cmp::NotEq),
            "and" => Instr::And,
            "or" => Instr::Or,
            "implies" => Instr::Implies,
            "iff" => Instr::Iff,
            "xor" => Instr::Xor,
            "until" => Instr::Until(window),
            "since" => Instr::Since(window),
            "unless" => {
                // rtamt's own reading: φ W ψ = always(φ) or (φ U ψ); with [a:b],
                // always[0:b](φ) or (φ U[a:b] ψ).
                let Some(w) = window else {
                    return Err(self.error(
                        "'unless' needs an interval, e.g. unless[0:5] (rtamt fails without one)"
                            .into(),
                    ));
                };
                let rhs_start = start_of_last(&self.code);
                let lhs: Vec<Instr> = self.code[lhs_start..rhs_start].to_vec();
                let rhs: Vec<Instr> = self.code[rhs_start..].to_vec();
                self.code.truncate(lhs_start);
                self.code.extend_from_slice(&lhs);
                self.code
                    .push(Instr::Always(Some(Window { begin: 0, ..w })));
                self.code.extend_from_slice(&lhs);
                self.code.extend_from_slice(&rhs);
                self.code.push(Instr::Until(Some(w)));
                Instr::Or
            }
            _ => unreachable!("binary_power knows every binary operator"),
        };
        self.code.push(instr);
        Ok(())
    }

    /// A primary or a prefix operator applied to its operand.
    fn prefix(&mut self) -> Result<(), ParseError> {
        let column = self.column();
        let tok = self.next();
        match tok {
            Tok::Num(v) => self.code.push(Instr::Const(v)),
            Tok::Name(name) => match (self.signal)(&name) {
                Some(i) => self.code.push(Instr::Signal(i)),
                None => {
                    let hint = if name.contains('/') || name.contains('.') {
                        " (rtamt reads '/' and '.' inside a name as part of it: put spaces round '/')"
                    } else {
                        ""
                    };
                    return Err(ParseError {
                        column,
                        message: format!(
                            "unknown signal '{name}'{hint}; the signals are {}",
                            self.known.join(", ")
                        ),
                    });
                }
            },
            Tok::Sym("(") => {
                self.expression(0)?;
                self.expect(")")?;
            }
            Tok::Sym("-") => {
                self.expression(NEGATION_OPERAND)?;
                self.code.push(Instr::Not);
            }
            Tok::Kw(f @ ("abs" | "sqrt" | "exp" | "rise" | "fall")) => {
                self.expect("(")?;
                self.expression(0)?;
                self.expect(")")?;
                self.code.push(match f {
                    "abs" => Instr::Abs,
                    "sqrt" => Instr::Sqrt,
                    "exp" => Instr::Exp,
                    "rise" => Instr::Rise,
                    _ => Instr::Fall,
                });
            }
            Tok::Kw("pow") => {
                self.expect("(")?;
                self.expression(0)?;
                self.expect(",")?;
                self.expression(0)?;
                self.expect(")")?;
                self.code.push(Instr::Pow);
            }
            Tok::Kw("not") => {
                self.expression(PREFIX_OPERAND)?;
                self.code.push(Instr::Not);
            }
            Tok::Kw(op @ ("always" | "eventually" | "historically" | "once")) => {
                let window = self.window()?;
                self.expression(PREFIX_OPERAND)?;
                self.code.push(match op {
                    "always" => Instr::Always(window),
                    "eventually" => Instr::Eventually(window),
                    "historically" => Instr::Historically(window),
                    _ => Instr::Once(window),
                });
            }
            Tok::Kw(op @ ("prev" | "next" | "s_prev" | "s_next")) => {
                self.expression(PREFIX_OPERAND)?;
                self.code.push(match op {
                    "prev" => Instr::Prev,
                    "next" => Instr::Next,
                    "s_prev" => Instr::StrongPrev,
                    _ => Instr::StrongNext,
                });
            }
            Tok::Kw(b @ ("true" | "false")) => {
                return Err(ParseError {
                    column,
                    message: format!(
                        "'{b}' is not an expression in rtamt's STL; write a comparison (e.g. 1 > 0)"
                    ),
                })
            }
            t => {
                return Err(ParseError {
                    column,
                    message: format!(
                        "expected a signal, a number, '(' or an operator, found {}",
                        t.describe()
                    ),
                })
            }
        }
        Ok(())
    }

    /// An optional interval `[a:b]` (or `[a,b]`), each bound a number with an optional unit
    /// (`s`, `ms`, `us`, `ns`; a begin without one takes the end's, and both default to
    /// seconds), in whole sampling periods.
    fn window(&mut self) -> Result<Option<Window>, ParseError> {
        if self.peek() != &Tok::Sym("[") {
            return Ok(None);
        }
        self.next();
        let (begin, begin_unit, begin_column) = self.bound()?;
        match self.peek() {
            Tok::Sym(":" | ",") => {
                self.next();
            }
            t => {
                return Err(self.error(format!(
                    "expected ':' in the interval, found {}",
                    t.describe()
                )))
            }
        }
        let (end, end_unit, end_column) = self.bound()?;
        self.expect("]")?;
        let end_unit = end_unit.unwrap_or(1.0);
        let begin_unit = begin_unit.unwrap_or(end_unit);
        let steps = |value: f64, unit: f64, column: usize| {
            let exact = value * unit / self.dt_s;
            let whole = exact.round();
            if (exact - whole).abs() > 1e-6 * whole.abs().max(1.0) || !exact.is_finite() {
                return Err(ParseError {
                    column,
                    message: format!(
                        "the bound {} s is not a whole number of steps of {} s",
                        value * unit,
                        self.dt_s
                    ),
                });
            }
            Ok(whole as usize)
        };
        let begin = steps(begin, begin_unit, begin_column)?;
        let end = steps(end, end_unit, end_column)?;
        if begin > end {
            return Err(ParseError {
                column: begin_column,
                message: "the interval's start is after its end".into(),
            });
        }
        Ok(Some(Window { begin, end }))
    }

    /// One bound: a non-negative number and its unit's length in seconds, if it has one.
    fn bound(&mut self) -> Result<(f64, Option<f64>, usize), ParseError> {
        let column = self.column();
        let value = match self.next() {
            Tok::Num(v) => v,
            t => {
                return Err(ParseError {
                    column,
                    message: format!("expected a time bound (a number), found {}", t.describe()),
                })
            }
        };
        let unit = match self.peek() {
            Tok::Kw("s") => Some(1.0),
            Tok::Kw("ms") => Some(1e-3),
            Tok::Kw("us") => Some(1e-6),
            Tok::Kw("ns") => Some(1e-9),
            _ => None,
        };
        if unit.is_some() {
            self.next();
        }
        Ok((value, unit, column))
    }
}

/// Where the last complete expression in `code` starts.
pub(super) fn start_of_last(code: &[Instr]) -> usize {
    let mut need = 1usize;
    let mut i = code.len();
    while need > 0 {
        i -= 1;
        need = need - 1 + code[i].arity();
    }
    i
}
