//! A small arithmetic expression language for scene formulas: time functions `φ(t)` and initial
//! gaps `g0(x, y)`.
//!
//! Grammar (usual precedence, `^` right-associative, binds tighter than unary minus):
//! numbers, the variables a formula is allowed to use, `pi`, `+ - * / ^`, parentheses and the
//! functions `sin cos tan exp ln sqrt abs min max`. Parsing happens once; evaluation walks a
//! small tree and never allocates.

use std::fmt;

/// Longest formula (bytes): bounds the depth of a chain of operators, which evaluation walks
/// recursively.
pub const MAX_FORMULA_LEN: usize = 4096;

/// Deepest nesting of parentheses, function calls, signs and powers the parser follows.
pub const MAX_NESTING: usize = 64;

/// A parsed formula. Variables are referenced by their index in the list given to [`Expr::parse`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Expr {
    source: String,
    root: Node,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
enum Node {
    Num(f64),
    Var(usize),
    Neg(Box<Node>),
    Bin(Op, Box<Node>, Box<Node>),
    Call1(Fun1, Box<Node>),
    Call2(Fun2, Box<Node>, Box<Node>),
}

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
enum Op {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
enum Fun1 {
    Sin,
    Cos,
    Tan,
    Exp,
    Ln,
    Sqrt,
    Abs,
}

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
enum Fun2 {
    Min,
    Max,
}

/// Why a formula could not be parsed; `position` is a byte offset into the formula.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("formula `{source_text}`: {problem} at position {position}")]
pub struct ExprError {
    pub source_text: String,
    pub problem: String,
    pub position: usize,
}

impl Expr {
    /// Parses `source`, allowing the variable names in `variables` (e.g. `["t"]`).
    pub fn parse(source: &str, variables: &[&str]) -> Result<Self, ExprError> {
        let mut p = Parser {
            src: source,
            bytes: source.as_bytes(),
            pos: 0,
            variables,
            depth: 0,
        };
        if source.len() > MAX_FORMULA_LEN {
            // Its beginning only: the whole would bury the message.
            let start: String = source.chars().take(60).collect();
            return Err(ExprError {
                source_text: format!("{start}…"),
                problem: format!("the formula is {} bytes long, at most {MAX_FORMULA_LEN}", source.len()),
                position: 0,
            });
        }
        let root = p.expr()?;
        p.skip_ws();
        if p.pos != p.bytes.len() {
            return Err(p.error("unexpected trailing input"));
        }
        Ok(Self {
            source: source.to_string(),
            root,
        })
    }

    /// The formula as written.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Evaluates with `values[i]` bound to the i-th variable given at parse time.
    pub fn eval(&self, values: &[f64]) -> f64 {
        eval(&self.root, values)
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.source)
    }
}

fn eval(node: &Node, v: &[f64]) -> f64 {
    match node {
        Node::Num(x) => *x,
        Node::Var(i) => v[*i],
        Node::Neg(a) => -eval(a, v),
        Node::Bin(op, a, b) => {
            let (a, b) = (eval(a, v), eval(b, v));
            match op {
                Op::Add => a + b,
                Op::Sub => a - b,
                Op::Mul => a * b,
                Op::Div => a / b,
                Op::Pow => a.powf(b),
            }
        }
        Node::Call1(f, a) => {
            let a = eval(a, v);
            match f {
                Fun1::Sin => a.sin(),
                Fun1::Cos => a.cos(),
                Fun1::Tan => a.tan(),
                Fun1::Exp => a.exp(),
                Fun1::Ln => a.ln(),
                Fun1::Sqrt => a.sqrt(),
                Fun1::Abs => a.abs(),
            }
        }
        Node::Call2(f, a, b) => {
            let (a, b) = (eval(a, v), eval(b, v));
            match f {
                Fun2::Min => a.min(b),
                Fun2::Max => a.max(b),
            }
        }
    }
}

struct Parser<'a> {
    src: &'a str,
    bytes: &'a [u8],
    pos: usize,
    variables: &'a [&'a str],
    /// Nesting of the `unary` calls in progress (every recursion of the grammar goes through it).
    depth: usize,
}

impl Parser<'_> {
    fn error(&self, problem: &str) -> ExprError {
        ExprError {
            source_text: self.src.to_string(),
            problem: problem.to_string(),
            position: self.pos,
        }
    }

    fn skip_ws(&mut self) {
        while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_ws();
        self.bytes.get(self.pos).copied()
    }

    fn expr(&mut self) -> Result<Node, ExprError> {
        let mut lhs = self.term()?;
        while let Some(c @ (b'+' | b'-')) = self.peek() {
            self.pos += 1;
            let rhs = self.term()?;
            let op = if c == b'+' { Op::Add } else { Op::Sub };
            lhs = Node::Bin(op, Box::new(lhs), Box::new(rhs));
        }
        Ok(lhs)
    }

    fn term(&mut self) -> Result<Node, ExprError> {
        let mut lhs = self.unary()?;
        while let Some(c @ (b'*' | b'/')) = self.peek() {
            self.pos += 1;
            let rhs = self.unary()?;
            let op = if c == b'*' { Op::Mul } else { Op::Div };
            lhs = Node::Bin(op, Box::new(lhs), Box::new(rhs));
        }
        Ok(lhs)
    }

    fn unary(&mut self) -> Result<Node, ExprError> {
        if self.depth >= MAX_NESTING {
            return Err(self.error(&format!("nested more than {MAX_NESTING} levels deep")));
        }
        self.depth += 1;
        let node = self.unary_inner();
        self.depth -= 1;
        node
    }

    fn unary_inner(&mut self) -> Result<Node, ExprError> {
        match self.peek() {
            Some(b'-') => {
                self.pos += 1;
                Ok(Node::Neg(Box::new(self.unary()?)))
            }
            Some(b'+') => {
                self.pos += 1;
                self.unary()
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<Node, ExprError> {
        let base = self.atom()?;
        if self.peek() == Some(b'^') {
            self.pos += 1;
            let exponent = self.unary()?;
            return Ok(Node::Bin(Op::Pow, Box::new(base), Box::new(exponent)));
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Node, ExprError> {
        match self.peek() {
            None => Err(self.error("unexpected end of formula")),
            Some(b'(') => {
                self.pos += 1;
                let inner = self.expr()?;
                if self.peek() != Some(b')') {
                    return Err(self.error("expected `)`"));
                }
                self.pos += 1;
                Ok(inner)
            }
            Some(c) if c.is_ascii_digit() || c == b'.' => self.number(),
            Some(c) if c.is_ascii_alphabetic() || c == b'_' => self.identifier(),
            Some(_) => Err(self.error("unexpected character")),
        }
    }

    fn number(&mut self) -> Result<Node, ExprError> {
        let start = self.pos;
        while self.pos < self.bytes.len() && (self.bytes[self.pos].is_ascii_digit() || self.bytes[self.pos] == b'.') {
            self.pos += 1;
        }
        if self.pos < self.bytes.len() && matches!(self.bytes[self.pos], b'e' | b'E') {
            let save = self.pos;
            self.pos += 1;
            if self.pos < self.bytes.len() && matches!(self.bytes[self.pos], b'+' | b'-') {
                self.pos += 1;
            }
            let digits = self.pos;
            while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_digit() {
                self.pos += 1;
            }
            if self.pos == digits {
                self.pos = save;
            }
        }
        let text = &self.src[start..self.pos];
        text.parse::<f64>().map(Node::Num).map_err(|_| {
            let mut e = self.error("malformed number");
            e.position = start;
            e
        })
    }

    fn identifier(&mut self) -> Result<Node, ExprError> {
        let start = self.pos;
        while self.pos < self.bytes.len()
            && (self.bytes[self.pos].is_ascii_alphanumeric() || self.bytes[self.pos] == b'_')
        {
            self.pos += 1;
        }
        let name = &self.src[start..self.pos];
        if let Some(i) = self.variables.iter().position(|v| *v == name) {
            return Ok(Node::Var(i));
        }
        if name == "pi" {
            return Ok(Node::Num(std::f64::consts::PI));
        }
        let f1 = match name {
            "sin" => Some(Fun1::Sin),
            "cos" => Some(Fun1::Cos),
            "tan" => Some(Fun1::Tan),
            "exp" => Some(Fun1::Exp),
            "ln" => Some(Fun1::Ln),
            "sqrt" => Some(Fun1::Sqrt),
            "abs" => Some(Fun1::Abs),
            _ => None,
        };
        let f2 = match name {
            "min" => Some(Fun2::Min),
            "max" => Some(Fun2::Max),
            _ => None,
        };
        if f1.is_none() && f2.is_none() {
            self.pos = start;
            let allowed = if self.variables.is_empty() {
                "none".to_string()
            } else {
                self.variables.join(", ")
            };
            return Err(self.error(&format!("unknown name `{name}` (variables allowed here: {allowed})")));
        }
        if self.peek() != Some(b'(') {
            return Err(self.error(&format!("expected `(` after `{name}`")));
        }
        self.pos += 1;
        let a = self.expr()?;
        let node = if let Some(f) = f1 {
            Node::Call1(f, Box::new(a))
        } else {
            if self.peek() != Some(b',') {
                return Err(self.error(&format!("`{name}` takes two arguments")));
            }
            self.pos += 1;
            let b = self.expr()?;
            Node::Call2(
                f2.expect("f1 or f2 is a function (checked above) and f1 is not"),
                Box::new(a),
                Box::new(b),
            )
        };
        if self.peek() != Some(b')') {
            return Err(self.error("expected `)`"));
        }
        self.pos += 1;
        Ok(node)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precedence_and_functions() {
        let e = Expr::parse("1 + 2*3^2 - -4/2", &[]).unwrap();
        assert_eq!(e.eval(&[]), 1.0 + 18.0 + 2.0);
        let e = Expr::parse("0.003*max(0, (t-0.5)/0.5)", &["t"]).unwrap();
        assert!((e.eval(&[0.75]) - 0.0015).abs() < 1e-15);
        assert_eq!(e.eval(&[0.25]), 0.0);
        let e = Expr::parse("x^2/(2*100)", &["x", "y"]).unwrap();
        assert!((e.eval(&[2.0, 0.0]) - 0.02).abs() < 1e-15);
        let e = Expr::parse("6000/30*sin(2*pi*t/10)", &["t"]).unwrap();
        assert!((e.eval(&[2.5]) - 200.0).abs() < 1e-12);
        let e = Expr::parse("-2^2", &[]).unwrap();
        assert_eq!(e.eval(&[]), -4.0);
        let e = Expr::parse("1.5e-3*2", &[]).unwrap();
        assert!((e.eval(&[]) - 3e-3).abs() < 1e-18);
    }

    #[test]
    fn errors_name_the_problem() {
        let e = Expr::parse("2*z", &["t"]).unwrap_err();
        assert!(e.problem.contains("unknown name `z`"), "{e}");
        assert_eq!(e.position, 2);
        assert!(Expr::parse("(1+2", &[]).unwrap_err().problem.contains("expected `)`"));
        assert!(Expr::parse("1 2", &[]).unwrap_err().problem.contains("trailing"));
        assert!(Expr::parse("max(1)", &[])
            .unwrap_err()
            .problem
            .contains("two arguments"));
    }

    /// Deep nesting and huge formulas are refused before they can exhaust the stack (a
    /// 20,000-deep formula used to abort the process).
    #[test]
    fn deep_or_huge_formulas_are_refused() {
        let deep = format!("{}t{}", "(".repeat(20_000), ")".repeat(20_000));
        assert!(Expr::parse(&deep, &["t"]).unwrap_err().problem.contains("bytes long"));
        let nested = format!("{}t{}", "(".repeat(100), ")".repeat(100));
        let e = Expr::parse(&nested, &["t"]).unwrap_err();
        assert!(e.problem.contains("nested more than 64 levels"), "{e}");
        let signs = format!("{}1", "-".repeat(1000));
        assert!(Expr::parse(&signs, &[]).unwrap_err().problem.contains("nested"));
        let ok = format!("{}t{}", "(".repeat(60), ")".repeat(60));
        assert_eq!(Expr::parse(&ok, &["t"]).unwrap().eval(&[2.0]), 2.0);
        let chain = vec!["t"; 2000].join("+");
        assert_eq!(Expr::parse(&chain, &["t"]).unwrap().eval(&[1.0]), 2000.0);
    }
}
