//! The program a generator builds before any dialect sees it: variables, expressions, moves
//! and do-while loops, and the interpreter that expands it into plain moves.
//!
//! A generator writes its loop once here. The loop form of every dialect is this program
//! rendered, and the expanded form is this program run by [`expand`] and rendered with
//! numbers only, so the two forms cannot drift apart except through rendering, which the
//! tests check by evaluating the rendered text independently.

pub use crate::setup::MachineStmt;

/// A variable of the program: `index` picks the ISO `#` number, `name` the SINUMERIK
/// `DEF REAL` name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Var {
    pub index: u16,
    pub name: &'static str,
}

/// An arithmetic expression. Angles in trigonometric functions are in degrees, as both
/// controls take them.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    Num(f64),
    Var(Var),
    Add(Box<Expr>, Box<Expr>),
    Sub(Box<Expr>, Box<Expr>),
    Mul(Box<Expr>, Box<Expr>),
    Div(Box<Expr>, Box<Expr>),
    Neg(Box<Expr>),
    Sin(Box<Expr>),
    Cos(Box<Expr>),
    Tan(Box<Expr>),
    Sqrt(Box<Expr>),
    Abs(Box<Expr>),
}

/// Sine of an angle in degrees, the one conversion every evaluator of our programs uses.
pub fn sin_deg(a: f64) -> f64 {
    a.to_radians().sin()
}
/// Cosine of an angle in degrees.
pub fn cos_deg(a: f64) -> f64 {
    a.to_radians().cos()
}
/// Tangent of an angle in degrees.
pub fn tan_deg(a: f64) -> f64 {
    a.to_radians().tan()
}

impl Expr {
    pub fn num(v: f64) -> Self {
        Expr::Num(v)
    }
    pub fn var(v: Var) -> Self {
        Expr::Var(v)
    }
    #[allow(clippy::should_implement_trait)]
    pub fn add(self, o: Expr) -> Self {
        Expr::Add(Box::new(self), Box::new(o))
    }
    #[allow(clippy::should_implement_trait)]
    pub fn sub(self, o: Expr) -> Self {
        Expr::Sub(Box::new(self), Box::new(o))
    }
    #[allow(clippy::should_implement_trait)]
    pub(crate) fn mul(self, o: Expr) -> Self {
        Expr::Mul(Box::new(self), Box::new(o))
    }
    #[allow(clippy::should_implement_trait)]
    pub fn div(self, o: Expr) -> Self {
        Expr::Div(Box::new(self), Box::new(o))
    }
    pub fn sin(self) -> Self {
        Expr::Sin(Box::new(self))
    }
    pub fn cos(self) -> Self {
        Expr::Cos(Box::new(self))
    }
    pub fn tan(self) -> Self {
        Expr::Tan(Box::new(self))
    }
    pub fn sqrt(self) -> Self {
        Expr::Sqrt(Box::new(self))
    }
    pub fn abs(self) -> Self {
        Expr::Abs(Box::new(self))
    }

    /// Value with the variables in `vars` (indexed by `Var::index`; unset variables are 0,
    /// as on both controls).
    pub fn eval(&self, vars: &Vars) -> f64 {
        match self {
            Expr::Num(v) => *v,
            Expr::Var(v) => vars.get(*v),
            Expr::Add(a, b) => a.eval(vars) + b.eval(vars),
            Expr::Sub(a, b) => a.eval(vars) - b.eval(vars),
            Expr::Mul(a, b) => a.eval(vars) * b.eval(vars),
            Expr::Div(a, b) => a.eval(vars) / b.eval(vars),
            Expr::Neg(a) => -a.eval(vars),
            Expr::Sin(a) => sin_deg(a.eval(vars)),
            Expr::Cos(a) => cos_deg(a.eval(vars)),
            Expr::Tan(a) => tan_deg(a.eval(vars)),
            Expr::Sqrt(a) => a.eval(vars).sqrt(),
            Expr::Abs(a) => a.eval(vars).abs(),
        }
    }
}

/// Variable values of a running program.
#[derive(Debug, Clone, Default)]
pub struct Vars(Vec<f64>);

impl Vars {
    pub fn get(&self, v: Var) -> f64 {
        self.0.get(usize::from(v.index)).copied().unwrap_or(0.0)
    }
    pub fn set(&mut self, v: Var, value: f64) {
        let i = usize::from(v.index);
        if self.0.len() <= i {
            self.0.resize(i + 1, 0.0);
        }
        self.0[i] = value;
    }
}

/// A comparison, `left < right` or `left > right`.
#[derive(Debug, Clone, PartialEq)]
pub struct Cond {
    pub left: Expr,
    pub less: bool,
    pub right: Expr,
}

impl Cond {
    pub fn holds(&self, vars: &Vars) -> bool {
        let (l, r) = (self.left.eval(vars), self.right.eval(vars));
        if self.less { l < r } else { l > r }
    }
}

/// Axis addresses the generators use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Axis {
    X,
    Y,
    Z,
    A,
    C,
    /// Arc centre, relative to the start, along X.
    I,
    /// Arc centre, relative to the start, along Y.
    J,
    /// Arc centre, relative to the start, along Z.
    K,
}

impl Axis {
    pub fn letter(self) -> char {
        match self {
            Axis::X => 'X',
            Axis::Y => 'Y',
            Axis::Z => 'Z',
            Axis::A => 'A',
            Axis::C => 'C',
            Axis::I => 'I',
            Axis::J => 'J',
            Axis::K => 'K',
        }
    }
    /// Rotary axes are written with the angle decimals.
    pub(crate) fn is_rotary(self) -> bool {
        matches!(self, Axis::A | Axis::C)
    }
}

/// Interpolation of a move.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    Rapid,
    Linear,
    ArcCw,
    ArcCcw,
}

/// Tool radius compensation state, in the plane's own orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compensation {
    Off,
    /// G41: tool left of the path, looking along the direction of travel.
    Left,
    /// G42: tool right of the path.
    Right,
}

/// Working plane of arcs and compensation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// G17, X–Y (turn-mill).
    Xy,
    /// G18, Z–X (turning).
    Zx,
}

/// One statement.
#[derive(Debug, Clone, PartialEq)]
pub enum Stmt {
    Comment(String),
    Assign(Var, Expr),
    Move {
        motion: Motion,
        words: Vec<(Axis, Expr)>,
        /// F word, in the unit of the feed mode in force ([`crate::setup::FeedMode`]:
        /// mm/min under G94, mm/rev under G95).
        feed: Option<f64>,
    },
    /// Machine state: work offset, X mode, tool, spindle, feed mode, coolant.
    Machine(MachineStmt),
    /// Calls the subprogram of that name (rendered beside the program that calls it).
    Call(String),
    /// The control's own stock removal from a contour subprogram (SINUMERIK `CYCLE95`).
    StockRemoval(StockRemoval),
    /// Compensation switched on or off; takes effect with the next move.
    Comp(Compensation),
    /// Runs `body`, then again while `cond` holds (at least once). `label` names the loop
    /// (SINUMERIK label, ISO O-word number).
    DoWhile {
        label: u16,
        body: Vec<Stmt>,
        cond: Cond,
    },
    /// Runs `body` once if `cond` holds.
    If {
        label: u16,
        cond: Cond,
        body: Vec<Stmt>,
    },
    /// Marks a point of the job (the end of a rotor segment); rendered as a comment and a
    /// parameter write the job can be resumed from.
    Mark {
        var: Var,
        value: f64,
        text: String,
    },
}

/// Roughing by the control's stock-removal cycle, longitudinal, outside: `CYCLE95` with
/// the contour subprogram `contour`.
#[derive(Debug, Clone, PartialEq)]
pub struct StockRemoval {
    pub contour: String,
    /// Largest infeed per cut, radius, mm.
    pub depth_mm: f64,
    /// Finishing allowance left along the contour, mm.
    pub allowance_mm: f64,
    /// Roughing feed, in the unit of the feed mode in force.
    pub feed: f64,
}

/// `program` with every [`Stmt::Call`] of one of `subs` replaced by that subprogram's body:
/// what the control runs, for the safety check and the expanded evaluation.
pub fn inline(program: &Program, subs: &[Program]) -> Program {
    fn go(body: &[Stmt], subs: &[Program]) -> Vec<Stmt> {
        body.iter()
            .flat_map(|s| match s {
                Stmt::Call(name) => match subs.iter().find(|p| &p.name == name) {
                    Some(p) => go(&p.body, subs),
                    None => vec![s.clone()],
                },
                other => vec![other.clone()],
            })
            .collect()
    }
    let mut vars = program.vars.clone();
    for p in subs {
        vars.extend(p.vars.iter().filter(|v| !program.vars.contains(v)));
    }
    Program {
        vars,
        body: go(&program.body, subs),
        ..program.clone()
    }
}

/// A program: its header facts and statements.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Program name, already checked against the control's rules.
    pub name: String,
    pub plane: Plane,
    /// Variables the program uses, declared first (SINUMERIK `DEF REAL`).
    pub vars: Vec<Var>,
    /// Comment lines after the header.
    pub comments: Vec<String>,
    pub body: Vec<Stmt>,
}

/// Loops run at most this many iterations in [`expand`]: a generator bug must not hang.
pub(crate) const MAX_ITERATIONS: usize = 1_000_000;

/// The program with every loop and condition run and every expression replaced by its
/// value: the expanded form. Marks are kept in place.
pub fn expand(program: &Program) -> Program {
    let mut vars = Vars::default();
    let mut out = Vec::new();
    run(&program.body, &mut vars, &mut out);
    Program {
        vars: Vec::new(),
        body: out,
        ..program.clone()
    }
}

fn run(body: &[Stmt], vars: &mut Vars, out: &mut Vec<Stmt>) {
    for s in body {
        match s {
            Stmt::Assign(v, e) => {
                let value = e.eval(vars);
                vars.set(*v, value);
            }
            Stmt::Move {
                motion,
                words,
                feed,
            } => out.push(Stmt::Move {
                motion: *motion,
                words: words
                    .iter()
                    .map(|(a, e)| (*a, Expr::Num(e.eval(vars))))
                    .collect(),
                feed: *feed,
            }),
            Stmt::DoWhile { body, cond, .. } => {
                for _ in 0..MAX_ITERATIONS {
                    run(body, vars, out);
                    if !cond.holds(vars) {
                        break;
                    }
                }
            }
            Stmt::If { cond, body, .. } => {
                if cond.holds(vars) {
                    run(body, vars, out);
                }
            }
            Stmt::Mark { var, value, .. } => {
                vars.set(*var, *value);
                out.push(s.clone());
            }
            Stmt::Comment(_)
            | Stmt::Comp(_)
            | Stmt::Machine(_)
            | Stmt::Call(_)
            | Stmt::StockRemoval(_) => out.push(s.clone()),
        }
    }
}
