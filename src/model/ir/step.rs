//! Step programs: the integrator's arithmetic around a model's field,
//! written once as data and printed to every generated target
//! (`model::codegen::step`): inlined into the C of the CPU's native step
//! loops, and as functions of the GPU's kernels in WGSL. The programs
//! themselves are in `model::ir::integrator`; this is their language.
//!
//! A program is a list of functions, each a block of statements ending in
//! its results. Values have six types (a number, a state vector, a pair
//! of numbers such as a forcing phase or an event's value and rate, a
//! truth value, a counter, an unsigned integer that bounds a loop or
//! indexes a state, and a structure). A structure is a function's several
//! results (read by member), one the program declares ([`Structure`]: a
//! stop, a Newton bracket), or an opaque one the kernels define (the
//! lane's parameters), passed on untouched; what the hand-written kernels
//! define and a program calls is declared too ([`Extern`]), so that every
//! name a program uses is typed. The kernels' buffers are such names,
//! read and written at an index, and their stores procedures a function
//! without results calls ([`Stmt::Do`]): so a kernel's whole per-lane
//! work is a program, and only its bindings and entry point are written
//! by hand.
//! The statements are what the integrator's loops need and no more: named
//! values ([`Stmt::Let`]), values that change ([`Stmt::Var`],
//! [`Stmt::Set`]), branches ([`Stmt::If`]) and loops left by a break
//! ([`Stmt::Loop`], [`Stmt::Break`]). A branch-free choice
//! ([`Expr::Select`]) is an expression of its own: a C loop over the slots
//! that branches per slot is not vectorised, one that selects is.
//!
//! The operations on states are componentwise, so a target without
//! vectors (C, one scalar per component) and one with them (WGSL) perform
//! the same IEEE operations in the same order. A field is an operation of
//! its own ([`Expr::Field`], the model's or the held flow's): each target
//! says how it is evaluated (C prints the model's tape in place, WGSL
//! calls the system file's `rhs` or the kernels' `held_rhs`).
//!
//! The Rust reference (`integrate::rk4`, `integrate::clock`,
//! `integrate::wall::may_reach`) stays written by hand: it is the oracle
//! the generated code is tested against, bit for bit (the native library's
//! tests and tests/step_loops.rs on the CPU, tests/gpu.rs and
//! tests/gpu_models.rs on the GPU).

use std::ops::{Add, Div, Mul, Sub};

/// What a value is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ty {
    Real,
    /// A state of the model's dimension.
    State,
    /// Two numbers: a forcing phase (cos ωt, sin ωt), or an event's
    /// value and rate.
    Pair,
    Bool,
    /// An unsigned integer (WGSL's `u32`, C's `uint32_t`): what counts a
    /// loop's passes, so that every loop has a bound the program states.
    Count,
    /// A structure: one the program declares ([`Structure`], its members
    /// read by [`Expr::Member`], made by [`Expr::Make`]), an opaque one
    /// the kernels define (the lane's `Params`, the stops' `Stops`: passed
    /// on, never read), or the results of a function with several
    /// ([`Function::returns`]).
    Struct(&'static str),
    /// A number per general surface, read by a counter: up to four
    /// (WGSL's `vec4<real>`; the surfaces' values g and rates).
    Table,
    /// A counter per general surface, read by a counter (WGSL's
    /// `vec4<u32>`: each surface's switch bit).
    CountTable,
    /// A square matrix of the model's dimension by rows, each a state
    /// (WGSL's `array<State, DIM>`: a reset's Jacobian, a saltation).
    Rows,
    /// A single-precision number whatever `real` is (WGSL's `f32`): what
    /// a part's summary records of a lane (its nonlinearity).
    Single,
}

/// A structure of named values (a stop, a Newton bracket). Without
/// members it is opaque: defined by the kernels, passed on untouched.
#[derive(Clone, Debug, PartialEq)]
pub struct Structure {
    pub name: &'static str,
    pub members: Vec<(&'static str, Ty)>,
}

/// What the hand-written kernels define and a program uses: a constant
/// (the number of stops `WALLS`), or a function (a stop by its index,
/// which reads the system file's tables).
#[derive(Clone, Debug, PartialEq)]
pub enum Extern {
    Const(&'static str, Ty),
    /// A structure the kernels define and make (the lane's `Params`, the
    /// surfaces' values), of which the program reads and sets the
    /// members named here and no others; it is not printed.
    Struct(&'static str, Vec<(&'static str, Ty)>),
    Fn {
        name: &'static str,
        params: Vec<Ty>,
        result: Ty,
    },
    /// A storage buffer of the kernels' bindings: an array of `element`s
    /// read at an index ([`Expr::Index`] of its name), and, `writable`,
    /// written at one ([`Stmt::SetAt`]). Never a value of its own.
    Buffer {
        name: &'static str,
        element: Ty,
        writable: bool,
    },
    /// A function of the kernels without a result (a store into their
    /// buffers), called by [`Stmt::Do`].
    Proc {
        name: &'static str,
        params: Vec<Ty>,
    },
}

/// A function of numbers the targets provide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Math {
    /// √x.
    Sqrt,
    /// The larger of two numbers.
    Max,
    /// The smaller of two numbers.
    Min,
    /// x clamped to [lo, hi] (WGSL's `clamp`).
    Clamp,
}

impl Math {
    pub fn name(self) -> &'static str {
        match self {
            Math::Sqrt => "sqrt",
            Math::Max => "max",
            Math::Min => "min",
            Math::Clamp => "clamp",
        }
    }

    /// How many numbers it takes.
    pub fn arity(self) -> usize {
        match self {
            Math::Sqrt => 1,
            Math::Max | Math::Min => 2,
            Math::Clamp => 3,
        }
    }
}

/// Which field a [`Expr::Field`] evaluates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    /// The model's field (WGSL's `rhs(p, phase, y)`).
    Model,
    /// The flow of a mass held at rest on a stop, its position and
    /// velocity fixed (`Held` of `integrate::impact::resolve`; WGSL's
    /// `held_rhs(p, w, phase, y)`, the stop `w` a parameter of every
    /// function that reads it). Only the kernels hold a mass in generated
    /// code: the CPU holds it in Rust.
    Held,
}

/// A value: an operation of named values and numbers.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    Var(&'static str),
    Num(f64),
    /// A counter's value.
    Count(u32),
    /// `+ - * /`; on states componentwise, a number times a state scales
    /// it; `+ -` and the bit operations `>> & | ^` on counters.
    Bin(Op, Box<Expr>, Box<Expr>),
    /// |x| of a number.
    Abs(Box<Expr>),
    /// Whether a number is neither infinite nor NaN.
    Finite(Box<Expr>),
    /// The state with every component this number.
    Fill(Box<Expr>),
    /// A pair's first number (a phase's cosine).
    First(Box<Expr>),
    /// A pair's second number (a phase's sine).
    Second(Box<Expr>),
    /// The pair of two numbers.
    Pair(Box<Expr>, Box<Expr>),
    /// A comparison of two numbers, or of two counters.
    Cmp(Cmp, Box<Expr>, Box<Expr>),
    /// Truth values: both, either, not (without short circuits: every
    /// operand is computed, as the vectorised C loops do).
    And(Box<Expr>, Box<Expr>),
    Or(Box<Expr>, Box<Expr>),
    Not(Box<Expr>),
    /// `then` where `cond` holds, else `otherwise`, both computed: a
    /// choice without a branch, which a C loop over the slots keeps
    /// vectorised (an [`Stmt::If`] there would not be).
    Select {
        cond: Box<Expr>,
        then: Box<Expr>,
        otherwise: Box<Expr>,
    },
    /// A field at a phase and a state.
    Field {
        of: Field,
        phase: Box<Expr>,
        state: Box<Expr>,
    },
    /// A function of the program defined before this one (its structure
    /// of results where it has several), or one the kernels define
    /// ([`Extern::Fn`]).
    Call(&'static str, Vec<Expr>),
    /// A truth value.
    Truth(bool),
    /// -x of a number (exact: not 0 - x, which loses the sign of 0).
    Neg(Box<Expr>),
    /// A function of numbers.
    Math(Math, Vec<Expr>),
    /// A structure's member (a result of a call with several).
    Member(Box<Expr>, &'static str),
    /// A structure the program declares, from its members in order.
    Make(&'static str, Vec<Expr>),
    /// A state's component at a counter (a stop's coordinate), or a
    /// table's entry (a surface's value, its bit).
    Index(Box<Expr>, Box<Expr>),
    /// An operation on one counter's bits.
    Bits(Bits, Box<Expr>),
    /// A number as a [`Ty::Single`] (rounded to it where `real` is f64).
    Single(Box<Expr>),
    /// Four counters as one [`Ty::CountTable`] (a trajectory's counts).
    Counters(Vec<Expr>),
    /// A state, a table or a matrix with every entry 0 (a step's
    /// crossings per surface before any).
    Zero(Ty),
    /// Whether two states differ in any component.
    Differs(Box<Expr>, Box<Expr>),
}

/// An operation on one counter's bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bits {
    /// Every bit flipped (`~`).
    Complement,
    /// The index of the lowest bit set, all ones for 0 (WGSL's
    /// `firstTrailingBit`): the switch a sliding region slides on.
    LowestSet,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    Add,
    Sub,
    Mul,
    Div,
    /// A counter's bits shifted right (a region's bit `b` is `r >> b & 1`).
    Shr,
    /// A counter's bits shifted left (region bit `b` is `1 << b`).
    Shl,
    /// A counter's bits: both, either, one of the two.
    BitAnd,
    BitOr,
    BitXor,
    /// The remainder of a counter's division (a ring's slot).
    Rem,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cmp {
    Less,
    Greater,
    LessEq,
    GreaterEq,
    Equal,
    NotEqual,
}

impl Cmp {
    pub fn symbol(self) -> &'static str {
        match self {
            Cmp::Less => "<",
            Cmp::Greater => ">",
            Cmp::LessEq => "<=",
            Cmp::GreaterEq => ">=",
            Cmp::Equal => "==",
            Cmp::NotEqual => "!=",
        }
    }
}

impl Op {
    /// The operation's text, the same in C and WGSL.
    pub fn symbol(self) -> &'static str {
        match self {
            Op::Add => "+",
            Op::Sub => "-",
            Op::Mul => "*",
            Op::Div => "/",
            Op::Shr => ">>",
            Op::Shl => "<<",
            Op::BitAnd => "&",
            Op::BitOr => "|",
            Op::BitXor => "^",
            Op::Rem => "%",
        }
    }

    /// An operation on a counter's bits, which only counters have.
    pub fn is_bitwise(self) -> bool {
        matches!(
            self,
            Op::Shr | Op::Shl | Op::BitAnd | Op::BitOr | Op::BitXor
        )
    }
}

/// A statement of a function's body. Every name is declared once in a
/// function (no shadowing), so a target that names every value after its
/// function's call site (the C inliner) cannot make two the same.
#[derive(Clone, Debug, PartialEq)]
pub enum Stmt {
    /// A named value, fixed once computed.
    Let(&'static str, Expr),
    /// A value that later statements may change.
    Var(&'static str, Expr),
    /// A new value of a [`Stmt::Var`], of the same type.
    Set(&'static str, Expr),
    /// The first block where the condition holds, else the second (empty
    /// for none). Its declarations end with it.
    If(Expr, Vec<Stmt>, Vec<Stmt>),
    /// The block again and again until a [`Stmt::Break`] in it (not in a
    /// loop inside it) leaves. A loop has one, and a bound: a counter it
    /// tests (lavapipe caps a kernel's loop passes, and a loop that cannot
    /// end is a bug on any target).
    Loop(Vec<Stmt>),
    /// Leaves the innermost loop.
    Break,
    /// A new value of one component (at a counter) of a state
    /// [`Stmt::Var`], of one entry of a table, or of one row of a matrix.
    SetAt(&'static str, Expr, Expr),
    /// A new value of one entry (at a row and a column) of a matrix
    /// [`Stmt::Var`].
    SetEntry(&'static str, Expr, Expr, Expr),
    /// A new value of one member of a structure [`Stmt::Var`] (a copy of
    /// the lane's parameters in another region).
    SetMember(&'static str, &'static str, Expr),
    /// A call for its effect ([`Expr::Call`]): of a function of the
    /// program without results, or of the kernels' [`Extern::Proc`].
    Do(Expr),
}

/// A function of a program: its parameters, its statements, and its
/// results, named (a target that returns several values as a structure
/// names it [`Function::returns`] with these fields).
#[derive(Clone, Debug)]
pub struct Function {
    pub name: &'static str,
    pub params: Vec<(&'static str, Ty)>,
    pub body: Vec<Stmt>,
    pub results: Vec<(&'static str, Expr)>,
    /// The structure of several results (`None` with one).
    pub returns: Option<&'static str>,
}

/// Functions in order, each calling only those before it, the
/// structures they declare, and what they use of the kernels.
#[derive(Clone, Debug, Default)]
pub struct Program {
    pub functions: Vec<Function>,
    pub structures: Vec<Structure>,
    pub externs: Vec<Extern>,
}

/// A name in scope while a function is typed.
#[derive(Clone, Copy, Debug)]
struct Binding {
    name: &'static str,
    ty: Ty,
    /// A [`Stmt::Var`], which [`Stmt::Set`] may change.
    mutable: bool,
}

impl Program {
    pub fn function(&self, name: &str) -> &Function {
        self.functions
            .iter()
            .find(|f| f.name == name)
            .unwrap_or_else(|| panic!("no step function {name}"))
    }

    /// The type of `e` where the named values have the types `scope`
    /// gives; panics on an ill-typed program (a program is a constant of
    /// the source, and `tests` type every one).
    pub fn type_of(&self, e: &Expr, scope: &dyn Fn(&str) -> Ty) -> Ty {
        let ty = |e: &Expr| self.type_of(e, scope);
        let expect = |e: &Expr, want: Ty, what: &str| {
            let got = ty(e);
            assert_eq!(got, want, "{what} of {got:?}");
        };
        match e {
            Expr::Var(name) => {
                assert!(
                    self.buffer(name).is_none(),
                    "{name} is a buffer: it is read at an index"
                );
                match self.constant(name) {
                    Some(ty) => ty,
                    None => scope(name),
                }
            }
            Expr::Num(_) => Ty::Real,
            Expr::Count(_) => Ty::Count,
            Expr::Truth(_) => Ty::Bool,
            Expr::Neg(a) => {
                expect(a, Ty::Real, "-x");
                Ty::Real
            }
            Expr::Index(y, i) => {
                expect(i, Ty::Count, "a component at");
                if let Some((element, _)) = named_buffer(self, y) {
                    return element;
                }
                match ty(y) {
                    Ty::State | Ty::Table => Ty::Real,
                    Ty::CountTable => Ty::Count,
                    Ty::Rows => Ty::State,
                    other => panic!("a component of {other:?}"),
                }
            }
            Expr::Bits(bits, a) => {
                expect(a, Ty::Count, &format!("{bits:?}"));
                Ty::Count
            }
            Expr::Differs(a, b) => {
                expect(a, Ty::State, "a state that differs");
                expect(b, Ty::State, "a state that differs");
                Ty::Bool
            }
            Expr::Zero(ty) => match ty {
                Ty::State | Ty::Table | Ty::CountTable | Ty::Rows => *ty,
                other => panic!("{other:?} has no zero"),
            },
            Expr::Member(..) | Expr::Make(..) | Expr::Call(..) => self.type_of_structured(e, scope),
            Expr::Math(..) | Expr::Single(..) | Expr::Counters(..) => {
                self.type_of_numbers(e, scope)
            }
            Expr::Abs(a) => {
                expect(a, Ty::Real, "|x|");
                Ty::Real
            }
            Expr::Finite(a) => {
                expect(a, Ty::Real, "finite");
                Ty::Bool
            }
            Expr::Fill(a) => {
                expect(a, Ty::Real, "a filled state");
                Ty::State
            }
            Expr::First(a) | Expr::Second(a) => {
                expect(a, Ty::Pair, "a number of a pair");
                Ty::Real
            }
            Expr::Pair(a, b) => {
                expect(a, Ty::Real, "a pair");
                expect(b, Ty::Real, "a pair");
                Ty::Pair
            }
            Expr::Cmp(cmp, a, b) => match (ty(a), ty(b)) {
                (Ty::Real, Ty::Real) | (Ty::Count, Ty::Count) => Ty::Bool,
                (a, b) => panic!("{a:?} {} {b:?} is not a comparison", cmp.symbol()),
            },
            Expr::And(a, b) | Expr::Or(a, b) => {
                expect(a, Ty::Bool, "a truth operation");
                expect(b, Ty::Bool, "a truth operation");
                Ty::Bool
            }
            Expr::Not(a) => {
                expect(a, Ty::Bool, "not");
                Ty::Bool
            }
            Expr::Select {
                cond,
                then,
                otherwise,
            } => {
                expect(cond, Ty::Bool, "a selection's condition");
                let t = ty(then);
                expect(otherwise, t, "a selection's other value");
                t
            }
            Expr::Field { phase, state, .. } => {
                expect(phase, Ty::Pair, "a field's phase");
                expect(state, Ty::State, "a field's state");
                Ty::State
            }
            Expr::Bin(op, a, b) => match (ty(a), ty(b)) {
                (Ty::Count, Ty::Count) if op.is_bitwise() || *op == Op::Rem => Ty::Count,
                _ if op.is_bitwise() || *op == Op::Rem => {
                    panic!("{} is an operation of two counters", op.symbol())
                }
                (Ty::Real, Ty::Real) => Ty::Real,
                (Ty::State, Ty::State) if matches!(op, Op::Add | Op::Sub) => Ty::State,
                (Ty::Count, Ty::Count) => Ty::Count,
                (Ty::Real, Ty::State) if *op == Op::Mul => Ty::State,
                (a, b) => panic!("{a:?} {} {b:?} is not a step operation", op.symbol()),
            },
        }
    }

    /// The type of a function of numbers, a single, or four counters.
    fn type_of_numbers(&self, e: &Expr, scope: &dyn Fn(&str) -> Ty) -> Ty {
        let ty = |e: &Expr| self.type_of(e, scope);
        let expect = |e: &Expr, want: Ty, what: &str| {
            let got = ty(e);
            assert_eq!(got, want, "{what} of {got:?}");
        };
        match e {
            Expr::Math(f, args) => {
                assert_eq!(args.len(), f.arity(), "{}'s arguments", f.name());
                // The larger or smaller of two singles, or of two
                // counters, is one too.
                let of = match (f, ty(&args[0])) {
                    (Math::Max | Math::Min, of @ (Ty::Single | Ty::Count)) => of,
                    _ => Ty::Real,
                };
                for a in args {
                    expect(a, of, f.name());
                }
                of
            }
            Expr::Single(a) => {
                expect(a, Ty::Real, "a single");
                Ty::Single
            }
            Expr::Counters(args) => {
                assert_eq!(args.len(), 4, "four counters");
                for a in args {
                    expect(a, Ty::Count, "four counters");
                }
                Ty::CountTable
            }
            _ => unreachable!("{e:?} is not a function of numbers, a single or counters"),
        }
    }

    /// The type of a member, a structure made, or a call.
    fn type_of_structured(&self, e: &Expr, scope: &dyn Fn(&str) -> Ty) -> Ty {
        let ty = |e: &Expr| self.type_of(e, scope);
        let expect = |e: &Expr, want: Ty, what: &str| {
            let got = ty(e);
            assert_eq!(got, want, "{what} of {got:?}");
        };
        match e {
            Expr::Member(a, member) => match ty(a) {
                Ty::Struct(name) => {
                    self.members(name)
                        .into_iter()
                        .find(|(m, _)| m == member)
                        .unwrap_or_else(|| panic!("{name} has no member {member}"))
                        .1
                }
                other => panic!("{other:?} has no members"),
            },
            Expr::Make(name, args) => {
                assert!(
                    self.kernels_structure(name).is_none(),
                    "{name} is the kernels': they make it"
                );
                let members = self.structure(name).members.clone();
                assert!(!members.is_empty(), "{name} is opaque: the kernels make it");
                assert_eq!(args.len(), members.len(), "{name}'s members");
                for (arg, (member, want)) in args.iter().zip(&members) {
                    expect(arg, *want, &format!("{name}'s {member}"));
                }
                Ty::Struct(name)
            }
            Expr::Call(name, args) => {
                assert!(
                    !self.has_no_result(name),
                    "{name} has no result: it is called by a statement"
                );
                if let Some((params, result)) = self.external(name) {
                    assert_eq!(args.len(), params.len(), "{name}'s arguments");
                    for (arg, want) in args.iter().zip(params) {
                        expect(arg, *want, &format!("{name}'s argument"));
                    }
                    return result;
                }
                let f = self.function(name);
                assert_eq!(args.len(), f.params.len(), "{name}'s arguments");
                for (arg, (param, want)) in args.iter().zip(&f.params) {
                    expect(arg, *want, &format!("{name}'s {param}"));
                }
                match f.returns {
                    Some(structure) => Ty::Struct(structure),
                    None => f.result_types(self)[0],
                }
            }
            _ => unreachable!("{e:?} is not a member, a structure or a call"),
        }
    }

    /// The type of the kernels' constant `name`, if it is one.
    fn constant(&self, name: &str) -> Option<Ty> {
        self.externs.iter().find_map(|e| match e {
            Extern::Const(n, ty) if *n == name => Some(*ty),
            _ => None,
        })
    }

    /// The parameters and result of the kernels' function `name`, if it
    /// is one.
    fn external(&self, name: &str) -> Option<(&[Ty], Ty)> {
        self.externs.iter().find_map(|e| match e {
            Extern::Fn {
                name: n,
                params,
                result,
            } if *n == name => Some((&params[..], *result)),
            _ => None,
        })
    }

    /// The element of the kernels' buffer `name`, and whether the
    /// program writes it, if it is one.
    fn buffer(&self, name: &str) -> Option<(Ty, bool)> {
        self.externs.iter().find_map(|e| match e {
            Extern::Buffer {
                name: n,
                element,
                writable,
            } if *n == name => Some((*element, *writable)),
            _ => None,
        })
    }

    /// Whether `name` is a function without a result: the kernels'
    /// procedure, or one of the program's without results.
    fn has_no_result(&self, name: &str) -> bool {
        let procedure = self
            .externs
            .iter()
            .any(|e| matches!(e, Extern::Proc { name: n, .. } if *n == name));
        procedure
            || self
                .functions
                .iter()
                .any(|f| f.name == name && f.results.is_empty())
    }

    /// The parameters of the function without a result `name`: the
    /// kernels' procedure's, or the program's function's.
    fn procedure(&self, name: &str) -> Vec<Ty> {
        let procedure = self.externs.iter().find_map(|e| match e {
            Extern::Proc { name: n, params } if *n == name => Some(params.clone()),
            _ => None,
        });
        if let Some(params) = procedure {
            return params;
        }
        let f = self.function(name);
        assert!(f.results.is_empty(), "{name} has results: they are used");
        f.params.iter().map(|(_, ty)| *ty).collect()
    }

    /// The members the program may use of the kernels' structure `name`,
    /// if it is one.
    fn kernels_structure(&self, name: &str) -> Option<&[(&'static str, Ty)]> {
        self.externs.iter().find_map(|e| match e {
            Extern::Struct(n, members) if *n == name => Some(&members[..]),
            _ => None,
        })
    }

    /// The structure `name` the program declares.
    pub fn structure(&self, name: &str) -> &Structure {
        self.structures
            .iter()
            .find(|s| s.name == name)
            .unwrap_or_else(|| panic!("no structure {name}"))
    }

    /// The members of structure `name`: a declared one's, or the results
    /// of the functions that return it. Panics on an opaque one.
    pub fn members(&self, name: &str) -> Vec<(&'static str, Ty)> {
        if let Some(f) = self.functions.iter().find(|f| f.returns == Some(name)) {
            let types = f.result_types(self);
            return f.results.iter().map(|(n, _)| *n).zip(types).collect();
        }
        if let Some(members) = self.kernels_structure(name) {
            return members.to_vec();
        }
        let members = self.structure(name).members.clone();
        assert!(
            !members.is_empty(),
            "{name} is opaque: its members are not read"
        );
        members
    }

    /// Types `block`'s statements with `scope` in force, adding to it
    /// what it declares (dropped by the caller where the block ends);
    /// `loops` counts the loops around it. Panics on an ill-typed
    /// statement, a name declared twice, a `Set` of a fixed value, a
    /// `Break` outside a loop, or a loop without one.
    fn check(&self, block: &[Stmt], scope: &mut Vec<Binding>, loops: usize) {
        for stmt in block {
            let ty = |e: &Expr, scope: &[Binding]| self.type_of(e, &|n| lookup(scope, n).ty);
            match stmt {
                Stmt::Let(name, e) | Stmt::Var(name, e) => {
                    assert!(
                        scope.iter().all(|b| b.name != *name)
                            && self.constant(name).is_none()
                            && self.buffer(name).is_none(),
                        "{name} is declared twice"
                    );
                    let ty = ty(e, scope);
                    let mutable = matches!(stmt, Stmt::Var(..));
                    scope.push(Binding { name, ty, mutable });
                }
                Stmt::Set(name, e) => {
                    let target = lookup(scope, name);
                    assert!(target.mutable, "{name} is not a var");
                    assert_eq!(ty(e, scope), target.ty, "{name}'s new value");
                }
                Stmt::If(cond, then, otherwise) => {
                    assert_eq!(ty(cond, scope), Ty::Bool, "a condition");
                    for block in [then, otherwise] {
                        let outer = scope.len();
                        self.check(block, scope, loops);
                        scope.truncate(outer);
                    }
                }
                Stmt::Loop(body) => {
                    assert!(breaks(body), "a loop without a break");
                    let outer = scope.len();
                    self.check(body, scope, loops + 1);
                    scope.truncate(outer);
                }
                Stmt::Break => assert!(loops > 0, "a break outside a loop"),
                Stmt::SetAt(name, i, e) => {
                    let component = match self.buffer(name) {
                        Some((element, writable)) => {
                            assert!(writable, "{name} is a buffer the program only reads");
                            element
                        }
                        None => {
                            let target = lookup(scope, name);
                            assert!(target.mutable, "{name} is not a var");
                            match target.ty {
                                Ty::State | Ty::Table => Ty::Real,
                                Ty::CountTable => Ty::Count,
                                Ty::Rows => Ty::State,
                                _ => panic!("{name} has no components"),
                            }
                        }
                    };
                    assert_eq!(ty(i, scope), Ty::Count, "{name}'s component at");
                    assert_eq!(ty(e, scope), component, "{name}'s new component");
                }
                Stmt::SetEntry(name, row, col, e) => {
                    let target = lookup(scope, name);
                    assert!(target.mutable, "{name} is not a var");
                    assert_eq!(target.ty, Ty::Rows, "{name} has no entries");
                    assert_eq!(ty(row, scope), Ty::Count, "{name}'s row");
                    assert_eq!(ty(col, scope), Ty::Count, "{name}'s column");
                    assert_eq!(ty(e, scope), Ty::Real, "{name}'s new entry");
                }
                Stmt::SetMember(name, member, e) => {
                    let target = lookup(scope, name);
                    assert!(target.mutable, "{name} is not a var");
                    let Ty::Struct(structure) = target.ty else {
                        panic!("{name} has no members")
                    };
                    let want = self
                        .members(structure)
                        .into_iter()
                        .find(|(m, _)| m == member)
                        .unwrap_or_else(|| panic!("{structure} has no member {member}"))
                        .1;
                    assert_eq!(ty(e, scope), want, "{name}.{member}'s new value");
                }
                Stmt::Do(call) => {
                    let Expr::Call(name, args) = call else {
                        panic!("a statement calls a function without results, not {call:?}")
                    };
                    let params = self.procedure(name);
                    assert_eq!(args.len(), params.len(), "{name}'s arguments");
                    for (arg, want) in args.iter().zip(params) {
                        assert_eq!(ty(arg, scope), want, "{name}'s argument");
                    }
                }
            }
        }
    }

    /// The names in scope at the end of `f`'s body, parameters first,
    /// every statement typed on the way.
    fn scope_at_end(&self, f: &Function) -> Vec<Binding> {
        for (name, _) in &f.params {
            assert!(
                self.constant(name).is_none() && self.buffer(name).is_none(),
                "{name} is declared twice"
            );
        }
        let mut scope: Vec<Binding> = f
            .params
            .iter()
            .map(|&(name, ty)| Binding {
                name,
                ty,
                mutable: false,
            })
            .collect();
        self.check(&f.body, &mut scope, 0);
        scope
    }
}

/// Whether `block` leaves its loop: a break in it, or in a branch of it
/// (one in a loop inside it leaves that loop).
fn breaks(block: &[Stmt]) -> bool {
    block.iter().any(|s| match s {
        Stmt::Break => true,
        Stmt::If(_, a, b) => breaks(a) || breaks(b),
        _ => false,
    })
}

impl Function {
    /// A function of one result, returned as it is (no structure).
    pub fn one(
        name: &'static str,
        params: Vec<(&'static str, Ty)>,
        body: Vec<Stmt>,
        result: (&'static str, Expr),
    ) -> Function {
        Function {
            name,
            params,
            body,
            results: vec![result],
            returns: None,
        }
    }

    /// The type of each result.
    pub fn result_types(&self, program: &Program) -> Vec<Ty> {
        let scope = program.scope_at_end(self);
        self.results
            .iter()
            .map(|(_, e)| program.type_of(e, &|n| lookup(&scope, n).ty))
            .collect()
    }

    /// Every expression of the function, its statements' (in branches
    /// and loops too) and its results'.
    pub fn exprs(&self) -> Vec<&Expr> {
        fn of<'a>(block: &'a [Stmt], out: &mut Vec<&'a Expr>) {
            for s in block {
                match s {
                    Stmt::Let(_, e) | Stmt::Var(_, e) | Stmt::Set(_, e) => out.push(e),
                    Stmt::If(c, a, b) => {
                        out.push(c);
                        of(a, out);
                        of(b, out);
                    }
                    Stmt::Loop(body) => of(body, out),
                    Stmt::Break => {}
                    Stmt::SetAt(_, i, e) => {
                        out.push(i);
                        out.push(e);
                    }
                    Stmt::SetMember(_, _, e) => out.push(e),
                    Stmt::SetEntry(_, row, col, e) => out.extend([row, col, e]),
                    Stmt::Do(call) => out.push(call),
                }
            }
        }
        let mut out = Vec::new();
        of(&self.body, &mut out);
        out.extend(self.results.iter().map(|(_, e)| e));
        out
    }
}

impl Expr {
    /// The expressions this one is an operation of.
    pub fn operands(&self) -> Vec<&Expr> {
        match self {
            Expr::Var(_) | Expr::Num(_) | Expr::Count(_) | Expr::Truth(_) | Expr::Zero(_) => {
                Vec::new()
            }
            Expr::Bin(_, a, b)
            | Expr::Index(a, b)
            | Expr::Pair(a, b)
            | Expr::Cmp(_, a, b)
            | Expr::And(a, b)
            | Expr::Or(a, b)
            | Expr::Differs(a, b) => vec![a, b],
            Expr::Abs(a)
            | Expr::Finite(a)
            | Expr::Fill(a)
            | Expr::First(a)
            | Expr::Second(a)
            | Expr::Neg(a)
            | Expr::Member(a, _)
            | Expr::Bits(_, a)
            | Expr::Single(a)
            | Expr::Not(a) => vec![a],
            Expr::Select {
                cond,
                then,
                otherwise,
            } => vec![cond, then, otherwise],
            Expr::Field { phase, state, .. } => vec![phase, state],
            Expr::Call(_, args)
            | Expr::Math(_, args)
            | Expr::Make(_, args)
            | Expr::Counters(args) => args.iter().collect(),
        }
    }
}

/// The element and writability of the buffer `e` names, if it names one.
fn named_buffer(program: &Program, e: &Expr) -> Option<(Ty, bool)> {
    match e {
        Expr::Var(name) => program.buffer(name),
        _ => None,
    }
}

fn lookup(scope: &[Binding], name: &str) -> Binding {
    *scope
        .iter()
        .rev()
        .find(|b| b.name == name)
        .unwrap_or_else(|| panic!("{name} is not in scope"))
}

impl<T: Into<Expr>> Add<T> for Expr {
    type Output = Expr;
    fn add(self, b: T) -> Expr {
        Expr::Bin(Op::Add, Box::new(self), Box::new(b.into()))
    }
}

impl<T: Into<Expr>> Sub<T> for Expr {
    type Output = Expr;
    fn sub(self, b: T) -> Expr {
        Expr::Bin(Op::Sub, Box::new(self), Box::new(b.into()))
    }
}

impl<T: Into<Expr>> Mul<T> for Expr {
    type Output = Expr;
    fn mul(self, b: T) -> Expr {
        Expr::Bin(Op::Mul, Box::new(self), Box::new(b.into()))
    }
}

impl<T: Into<Expr>> Div<T> for Expr {
    type Output = Expr;
    fn div(self, b: T) -> Expr {
        Expr::Bin(Op::Div, Box::new(self), Box::new(b.into()))
    }
}

impl From<f64> for Expr {
    fn from(v: f64) -> Expr {
        Expr::Num(v)
    }
}

impl From<&'static str> for Expr {
    fn from(name: &'static str) -> Expr {
        Expr::Var(name)
    }
}

/// Short forms that keep the programs readable.
pub mod build {
    use super::{Bits, Cmp, Expr, Field, Math, Op, Stmt, Ty};

    pub fn var(name: &'static str) -> Expr {
        Expr::Var(name)
    }

    pub fn num(v: f64) -> Expr {
        Expr::Num(v)
    }

    pub fn count(n: u32) -> Expr {
        Expr::Count(n)
    }

    /// `a >> b`, `a & b`, `a | b`, `a ^ b` of two counters.
    pub fn shr(a: Expr, b: Expr) -> Expr {
        Expr::Bin(Op::Shr, Box::new(a), Box::new(b))
    }

    pub fn bit_and(a: Expr, b: Expr) -> Expr {
        Expr::Bin(Op::BitAnd, Box::new(a), Box::new(b))
    }

    pub fn bit_or(a: Expr, b: Expr) -> Expr {
        Expr::Bin(Op::BitOr, Box::new(a), Box::new(b))
    }

    pub fn bit_xor(a: Expr, b: Expr) -> Expr {
        Expr::Bin(Op::BitXor, Box::new(a), Box::new(b))
    }

    pub fn shl(a: Expr, b: Expr) -> Expr {
        Expr::Bin(Op::Shl, Box::new(a), Box::new(b))
    }

    /// `~a`.
    pub fn complement(a: Expr) -> Expr {
        Expr::Bits(Bits::Complement, Box::new(a))
    }

    /// The index of `a`'s lowest bit set (`firstTrailingBit`).
    pub fn lowest_set(a: Expr) -> Expr {
        Expr::Bits(Bits::LowestSet, Box::new(a))
    }

    pub fn abs(a: Expr) -> Expr {
        Expr::Abs(Box::new(a))
    }

    pub fn finite(a: Expr) -> Expr {
        Expr::Finite(Box::new(a))
    }

    pub fn fill(a: Expr) -> Expr {
        Expr::Fill(Box::new(a))
    }

    pub fn first(a: Expr) -> Expr {
        Expr::First(Box::new(a))
    }

    pub fn second(a: Expr) -> Expr {
        Expr::Second(Box::new(a))
    }

    /// A phase's cosine.
    pub fn cos(phase: &'static str) -> Expr {
        first(var(phase))
    }

    /// A phase's sine.
    pub fn sin(phase: &'static str) -> Expr {
        second(var(phase))
    }

    pub fn pair(a: Expr, b: Expr) -> Expr {
        Expr::Pair(Box::new(a), Box::new(b))
    }

    pub fn cmp(cmp: Cmp, a: Expr, b: Expr) -> Expr {
        Expr::Cmp(cmp, Box::new(a), Box::new(b))
    }

    pub fn greater(a: Expr, b: Expr) -> Expr {
        cmp(Cmp::Greater, a, b)
    }

    pub fn less(a: Expr, b: Expr) -> Expr {
        cmp(Cmp::Less, a, b)
    }

    pub fn and(a: Expr, b: Expr) -> Expr {
        Expr::And(Box::new(a), Box::new(b))
    }

    pub fn or(a: Expr, b: Expr) -> Expr {
        Expr::Or(Box::new(a), Box::new(b))
    }

    pub fn not(a: Expr) -> Expr {
        Expr::Not(Box::new(a))
    }

    pub fn select(cond: Expr, then: Expr, otherwise: Expr) -> Expr {
        Expr::Select {
            cond: Box::new(cond),
            then: Box::new(then),
            otherwise: Box::new(otherwise),
        }
    }

    pub fn field(of: Field, phase: &'static str, state: Expr) -> Expr {
        Expr::Field {
            of,
            phase: Box::new(var(phase)),
            state: Box::new(state),
        }
    }

    pub fn call(name: &'static str, args: &[&'static str]) -> Expr {
        Expr::Call(name, args.iter().map(|&a| var(a)).collect())
    }

    /// A call with arguments of any expression.
    pub fn apply(name: &'static str, args: Vec<Expr>) -> Expr {
        Expr::Call(name, args)
    }

    pub fn truth(v: bool) -> Expr {
        Expr::Truth(v)
    }

    pub fn neg(a: Expr) -> Expr {
        Expr::Neg(Box::new(a))
    }

    pub fn sqrt(a: Expr) -> Expr {
        Expr::Math(Math::Sqrt, vec![a])
    }

    pub fn max(a: Expr, b: Expr) -> Expr {
        Expr::Math(Math::Max, vec![a, b])
    }

    pub fn min(a: Expr, b: Expr) -> Expr {
        Expr::Math(Math::Min, vec![a, b])
    }

    pub fn clamp(x: Expr, lo: Expr, hi: Expr) -> Expr {
        Expr::Math(Math::Clamp, vec![x, lo, hi])
    }

    /// `of.member`.
    pub fn member(of: Expr, member: &'static str) -> Expr {
        Expr::Member(Box::new(of), member)
    }

    /// The member of the named value `of`.
    pub fn dot(of: &'static str, member: &'static str) -> Expr {
        Expr::Member(Box::new(var(of)), member)
    }

    pub fn make(name: &'static str, members: Vec<Expr>) -> Expr {
        Expr::Make(name, members)
    }

    /// Whether the states a and b differ in any component.
    pub fn differs(a: Expr, b: Expr) -> Expr {
        Expr::Differs(Box::new(a), Box::new(b))
    }

    /// `ty` with every entry 0.
    pub fn zero(ty: Ty) -> Expr {
        Expr::Zero(ty)
    }

    /// `y[i]`.
    pub fn index(y: Expr, i: Expr) -> Expr {
        Expr::Index(Box::new(y), Box::new(i))
    }

    /// Named values in order.
    pub fn lets(values: Vec<(&'static str, Expr)>) -> Vec<Stmt> {
        values.into_iter().map(|(n, e)| Stmt::Let(n, e)).collect()
    }

    /// Leaves the loop unless `cond` holds: a `while`'s test.
    pub fn break_unless(cond: Expr) -> Stmt {
        Stmt::If(not(cond), vec![Stmt::Break], Vec::new())
    }

    /// `a % b` of two counters.
    pub fn rem(a: Expr, b: Expr) -> Expr {
        Expr::Bin(Op::Rem, Box::new(a), Box::new(b))
    }

    /// A number as a single.
    pub fn single(a: Expr) -> Expr {
        Expr::Single(Box::new(a))
    }

    /// Four counters as one table.
    pub fn counters(a: [Expr; 4]) -> Expr {
        Expr::Counters(a.into())
    }

    /// A call for its effect.
    pub fn perform(name: &'static str, args: Vec<Expr>) -> Stmt {
        Stmt::Do(Expr::Call(name, args))
    }
}

#[cfg(test)]
mod tests {
    use super::build::*;
    use super::*;

    fn one(params: Vec<(&'static str, Ty)>, body: Vec<Stmt>, result: Expr) -> Program {
        Program {
            functions: vec![Function {
                name: "f",
                params,
                body,
                results: vec![("r", result)],
                returns: None,
            }],
            ..Program::default()
        }
    }

    fn result_type(program: &Program) -> Ty {
        program.function("f").result_types(program)[0]
    }

    #[test]
    #[should_panic(expected = "is not a step operation")]
    fn a_state_times_a_state_is_refused() {
        let program = Program::default();
        let scope = |_: &str| Ty::State;
        program.type_of(&(var("y") * "y"), &scope);
    }

    #[test]
    fn a_counted_loop_with_a_select_is_typed() {
        let program = one(
            vec![("x", Ty::Real), ("y", Ty::State)],
            vec![
                Stmt::Var("n", count(0)),
                Stmt::Var("z", var("y")),
                Stmt::Loop(vec![
                    break_unless(less(var("n"), count(3))),
                    Stmt::Let("big", greater(abs(var("x")), num(1.0))),
                    Stmt::Set("z", select(var("big"), var("z") + "y", var("z"))),
                    Stmt::Set("n", var("n") + count(1)),
                ]),
                Stmt::If(
                    cmp(Cmp::Equal, var("n"), count(3)),
                    vec![Stmt::Set("z", var("x") * "z")],
                    Vec::new(),
                ),
            ],
            var("z"),
        );
        assert_eq!(result_type(&program), Ty::State);
    }

    #[test]
    #[should_panic(expected = "big is not in scope")]
    fn a_loop_s_values_end_with_it() {
        let body = vec![Stmt::Loop(vec![
            Stmt::Let("big", greater(var("x"), num(1.0))),
            Stmt::Break,
        ])];
        result_type(&one(vec![("x", Ty::Real)], body, var("big")));
    }

    #[test]
    #[should_panic(expected = "x is not a var")]
    fn a_parameter_is_not_set() {
        let body = vec![Stmt::Set("x", num(1.0))];
        result_type(&one(vec![("x", Ty::Real)], body, var("x")));
    }

    #[test]
    #[should_panic(expected = "n's new value")]
    fn a_counter_holds_no_number() {
        let body = vec![Stmt::Var("n", count(0)), Stmt::Set("n", num(1.0))];
        result_type(&one(vec![("x", Ty::Real)], body, var("x")));
    }

    #[test]
    #[should_panic(expected = "a loop without a break")]
    fn a_loop_has_a_break() {
        let body = vec![Stmt::Var("n", count(0)), Stmt::Loop(Vec::new())];
        result_type(&one(vec![("x", Ty::Real)], body, var("x")));
    }

    #[test]
    #[should_panic(expected = "a break outside a loop")]
    fn a_break_is_in_a_loop() {
        result_type(&one(vec![("x", Ty::Real)], vec![Stmt::Break], var("x")));
    }

    #[test]
    #[should_panic(expected = "x is declared twice")]
    fn a_name_is_declared_once() {
        let body = vec![Stmt::Let("x", num(1.0))];
        result_type(&one(vec![("x", Ty::Real)], body, var("x")));
    }

    #[test]
    #[should_panic(expected = "a selection's other value")]
    fn a_selection_chooses_between_values_of_one_type() {
        let e = select(greater(var("x"), num(0.0)), var("x"), var("y"));
        result_type(&one(vec![("x", Ty::Real), ("y", Ty::State)], vec![], e));
    }

    #[test]
    fn bit_operations_of_counters_are_counters() {
        let params = vec![("region", Ty::Count), ("bit", Ty::Count)];
        let side = bit_and(shr(var("region"), var("bit")), count(1));
        let e = bit_xor(bit_or(var("region"), side), count(4));
        assert_eq!(result_type(&one(params, vec![], e)), Ty::Count);
    }

    #[test]
    #[should_panic(expected = ">> is an operation of two counters")]
    fn a_number_has_no_bits() {
        let e = shr(var("x"), var("x"));
        result_type(&one(vec![("x", Ty::Real)], vec![], e));
    }

    #[test]
    #[should_panic(expected = "& is an operation of two counters")]
    fn a_counter_and_a_number_have_no_common_bits() {
        let e = bit_and(var("n"), var("x"));
        result_type(&one(vec![("n", Ty::Count), ("x", Ty::Real)], vec![], e));
    }

    /// A program with a declared structure, an opaque one, a constant and
    /// a function of the kernels: the stops' shapes.
    fn with_stops(params: Vec<(&'static str, Ty)>, body: Vec<Stmt>, result: Expr) -> Program {
        let mut program = one(params, body, result);
        program.structures = vec![
            Structure {
                name: "Stop",
                members: vec![("position", Ty::Real), ("coordinate", Ty::Count)],
            },
            Structure {
                name: "Stops",
                members: Vec::new(),
            },
        ];
        program.externs = vec![
            Extern::Const("WALLS", Ty::Count),
            Extern::Fn {
                name: "stop",
                params: vec![Ty::Struct("Stops"), Ty::Count],
                result: Ty::Struct("Stop"),
            },
        ];
        program
    }

    #[test]
    fn structures_constants_and_components_are_typed() {
        let params = vec![("walls", Ty::Struct("Stops")), ("y", Ty::State)];
        let body = vec![
            Stmt::Let("w", apply("stop", vec![var("walls"), var("WALLS")])),
            Stmt::Var("out", var("y")),
            Stmt::SetAt("out", dot("w", "coordinate"), neg(dot("w", "position"))),
            Stmt::Let("moved", make("Stop", vec![num(1.0), count(0)])),
            Stmt::Let(
                "g",
                clamp(
                    sqrt(index(var("out"), dot("moved", "coordinate"))),
                    max(num(0.0), num(-1.0)),
                    num(1.0),
                ),
            ),
        ];
        let program = with_stops(params, body, select(truth(true), var("g"), num(0.0)));
        assert_eq!(result_type(&program), Ty::Real);
    }

    #[test]
    fn a_call_with_several_results_is_their_structure() {
        let mut program = one(vec![("x", Ty::Real)], vec![], var("x"));
        program.functions[0].results.push(("twice", var("x") + "x"));
        program.functions[0].returns = Some("Two");
        program.functions.push(Function {
            name: "g",
            params: vec![("x", Ty::Real)],
            body: lets(vec![("both", call("f", &["x"]))]),
            results: vec![("r", dot("both", "twice"))],
            returns: None,
        });
        assert_eq!(program.function("g").result_types(&program), [Ty::Real]);
    }

    #[test]
    #[should_panic(expected = "Stop has no member speed")]
    fn a_structure_has_the_members_it_declares() {
        let body = lets(vec![("w", make("Stop", vec![num(1.0), count(0)]))]);
        result_type(&with_stops(vec![], body, dot("w", "speed")));
    }

    #[test]
    #[should_panic(expected = "Stops is opaque: its members are not read")]
    fn an_opaque_structure_is_not_read() {
        let params = vec![("walls", Ty::Struct("Stops"))];
        result_type(&with_stops(params, vec![], dot("walls", "position")));
    }

    #[test]
    #[should_panic(expected = "Stops is opaque: the kernels make it")]
    fn an_opaque_structure_is_not_made() {
        result_type(&with_stops(vec![], vec![], make("Stops", vec![])));
    }

    #[test]
    #[should_panic(expected = "Stop's coordinate of Real")]
    fn a_structure_is_made_of_its_members_types() {
        let e = dot_of_made(make("Stop", vec![num(1.0), num(0.0)]));
        result_type(&with_stops(vec![], vec![], e));
    }

    fn dot_of_made(made: Expr) -> Expr {
        member(made, "position")
    }

    #[test]
    #[should_panic(expected = "Real has no members")]
    fn a_number_has_no_members() {
        result_type(&one(vec![("x", Ty::Real)], vec![], dot("x", "position")));
    }

    #[test]
    #[should_panic(expected = "a component at of Real")]
    fn a_state_is_indexed_by_a_counter() {
        let params = vec![("y", Ty::State), ("x", Ty::Real)];
        result_type(&one(params, vec![], index(var("y"), var("x"))));
    }

    #[test]
    #[should_panic(expected = "y is not a var")]
    fn a_parameter_s_component_is_not_set() {
        let params = vec![("y", Ty::State)];
        let body = vec![Stmt::SetAt("y", count(0), num(1.0))];
        result_type(&one(params, body, var("y")));
    }

    #[test]
    #[should_panic(expected = "z has no components")]
    fn a_number_has_no_components_to_set() {
        let body = vec![
            Stmt::Var("z", num(0.0)),
            Stmt::SetAt("z", count(0), num(1.0)),
        ];
        result_type(&one(vec![], body, var("z")));
    }

    #[test]
    #[should_panic(expected = "WALLS is declared twice")]
    fn a_kernel_s_constant_is_not_shadowed() {
        let body = vec![Stmt::Let("WALLS", count(1))];
        result_type(&with_stops(vec![], body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "stop's argument of Real")]
    fn a_kernel_s_function_takes_its_parameters_types() {
        let params = vec![("walls", Ty::Struct("Stops"))];
        let e = dot_of_made(apply("stop", vec![var("walls"), num(0.0)]));
        result_type(&with_stops(params, vec![], e));
    }

    #[test]
    #[should_panic(expected = "clamp's arguments")]
    fn a_function_of_numbers_takes_its_arity() {
        let e = Expr::Math(Math::Clamp, vec![num(0.0), num(1.0)]);
        result_type(&one(vec![], vec![], e));
    }

    #[test]
    #[should_panic(expected = "-x of Bool")]
    fn a_truth_value_is_not_negated() {
        result_type(&one(vec![], vec![], neg(truth(false))));
    }

    /// A program with the kernels' `Params` (its region read and set)
    /// and a table of a number and of a counter per surface.
    fn with_params(params: Vec<(&'static str, Ty)>, body: Vec<Stmt>, result: Expr) -> Program {
        let mut program = one(params, body, result);
        program.externs = vec![
            Extern::Struct("Params", vec![("region", Ty::Count)]),
            Extern::Const("G", Ty::Table),
            Extern::Const("BITS", Ty::CountTable),
        ];
        program
    }

    #[test]
    fn tables_members_and_bits_are_typed() {
        let params = vec![("p", Ty::Struct("Params")), ("j", Ty::Count)];
        let body = vec![
            Stmt::Var("q", var("p")),
            Stmt::SetMember(
                "q",
                "region",
                bit_and(
                    dot("p", "region"),
                    complement(shl(count(1), index(var("BITS"), var("j")))),
                ),
            ),
            Stmt::Let("first", lowest_set(dot("q", "region"))),
        ];
        let program = with_params(params.clone(), body, index(var("G"), var("first")));
        assert_eq!(result_type(&program), Ty::Real);
        let bit = index(var("BITS"), var("j"));
        assert_eq!(result_type(&with_params(params, vec![], bit)), Ty::Count);
    }

    #[test]
    #[should_panic(expected = "p is not a var")]
    fn a_parameter_s_member_is_not_set() {
        let body = vec![Stmt::SetMember("p", "region", count(0))];
        let params = vec![("p", Ty::Struct("Params"))];
        result_type(&with_params(params, body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "Params has no member omega")]
    fn only_the_kernels_structure_s_declared_members_are_set() {
        let body = vec![
            Stmt::Var("q", var("p")),
            Stmt::SetMember("q", "omega", num(1.0)),
        ];
        let params = vec![("p", Ty::Struct("Params"))];
        result_type(&with_params(params, body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "q.region's new value")]
    fn a_member_is_set_to_a_value_of_its_type() {
        let body = vec![
            Stmt::Var("q", var("p")),
            Stmt::SetMember("q", "region", num(1.0)),
        ];
        let params = vec![("p", Ty::Struct("Params"))];
        result_type(&with_params(params, body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "x has no members")]
    fn a_number_has_no_member_to_set() {
        let body = vec![
            Stmt::Var("x", num(0.0)),
            Stmt::SetMember("x", "region", count(0)),
        ];
        result_type(&with_params(vec![], body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "Params is the kernels': they make it")]
    fn the_kernels_structure_is_not_made() {
        result_type(&with_params(vec![], vec![], make("Params", vec![count(0)])));
    }

    #[test]
    #[should_panic(expected = "Complement of Real")]
    fn a_number_has_no_bits_to_flip() {
        result_type(&with_params(vec![], vec![], complement(num(1.0))));
    }

    #[test]
    #[should_panic(expected = "LowestSet of Bool")]
    fn a_truth_value_has_no_lowest_bit() {
        result_type(&with_params(vec![], vec![], lowest_set(truth(true))));
    }

    #[test]
    #[should_panic(expected = "<< is an operation of two counters")]
    fn a_number_is_not_shifted() {
        let e = shl(count(1), num(2.0));
        result_type(&with_params(vec![], vec![], e));
    }

    #[test]
    #[should_panic(expected = "a component of Pair")]
    fn a_pair_is_not_a_table() {
        let e = index(pair(num(0.0), num(1.0)), count(0));
        result_type(&with_params(vec![], vec![], e));
    }

    #[test]
    fn a_matrix_s_rows_and_entries_are_typed() {
        let params = vec![("a", Ty::Rows), ("y", Ty::State)];
        let body = vec![
            Stmt::Var("s", var("a")),
            Stmt::SetAt("s", count(1), var("y")),
            Stmt::SetEntry("s", count(0), count(1), num(2.0)),
        ];
        let e = index(index(var("s"), count(0)), count(1));
        assert_eq!(result_type(&one(params, body, e)), Ty::Real);
    }

    #[test]
    #[should_panic(expected = "s's new component")]
    fn a_matrix_s_row_is_a_state() {
        let body = vec![
            Stmt::Var("s", var("a")),
            Stmt::SetAt("s", count(1), num(0.0)),
        ];
        result_type(&one(vec![("a", Ty::Rows)], body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "z has no entries")]
    fn a_state_has_no_entries() {
        let body = vec![
            Stmt::Var("z", var("y")),
            Stmt::SetEntry("z", count(0), count(0), num(0.0)),
        ];
        result_type(&one(vec![("y", Ty::State)], body, num(0.0)));
    }

    #[test]
    fn a_table_s_entries_are_set_and_zero_is_of_its_type() {
        let body = vec![
            Stmt::Var("n", zero(Ty::CountTable)),
            Stmt::SetAt("n", var("j"), index(var("n"), var("j")) + count(1)),
            Stmt::Var("g", zero(Ty::Table)),
            Stmt::SetAt("g", count(0), num(1.0)),
            Stmt::Let("y", zero(Ty::State)),
        ];
        let program = one(vec![("j", Ty::Count)], body, var("n"));
        assert_eq!(result_type(&program), Ty::CountTable);
    }

    #[test]
    #[should_panic(expected = "n's new component")]
    fn a_counter_table_holds_counters() {
        let body = vec![
            Stmt::Var("n", zero(Ty::CountTable)),
            Stmt::SetAt("n", count(0), num(1.0)),
        ];
        result_type(&one(vec![], body, var("n")));
    }

    #[test]
    fn states_that_differ_are_a_truth_value() {
        let params = vec![("a", Ty::State), ("b", Ty::State)];
        let e = differs(var("a"), var("b"));
        assert_eq!(result_type(&one(params, vec![], e)), Ty::Bool);
    }

    #[test]
    #[should_panic(expected = "a state that differs of Real")]
    fn only_states_differ() {
        let params = vec![("a", Ty::State), ("x", Ty::Real)];
        result_type(&one(params, vec![], differs(var("a"), var("x"))));
    }

    #[test]
    #[should_panic(expected = "Real has no zero")]
    fn a_number_has_no_zero_of_entries() {
        result_type(&one(vec![], vec![], zero(Ty::Real)));
    }

    #[test]
    #[should_panic(expected = "Struct(\"Stop\") has no zero")]
    fn a_structure_has_no_zero() {
        result_type(&with_stops(vec![], vec![], zero(Ty::Struct("Stop"))));
    }

    #[test]
    #[should_panic(expected = "a is not a var")]
    fn a_parameter_s_entry_is_not_set() {
        let body = vec![Stmt::SetEntry("a", count(0), count(0), num(0.0))];
        result_type(&one(vec![("a", Ty::Rows)], body, num(0.0)));
    }

    /// A program with the kernels' buffers (one only read), a procedure
    /// and a function of the program without results.
    fn with_buffers(body: Vec<Stmt>, result: Expr) -> Program {
        let mut program = one(vec![("t", Ty::Count), ("y", Ty::State)], body, result);
        program.externs = vec![
            Extern::Buffer {
                name: "traj",
                element: Ty::Real,
                writable: true,
            },
            Extern::Buffer {
                name: "counts",
                element: Ty::CountTable,
                writable: true,
            },
            Extern::Buffer {
                name: "lanes",
                element: Ty::Real,
                writable: false,
            },
            Extern::Proc {
                name: "store",
                params: vec![Ty::Count, Ty::State],
            },
        ];
        program.functions.insert(
            0,
            Function {
                name: "clear",
                params: vec![("at", Ty::Count)],
                body: vec![Stmt::SetAt("traj", var("at"), num(0.0))],
                results: Vec::new(),
                returns: None,
            },
        );
        program
    }

    #[test]
    fn buffers_procedures_singles_and_counters_are_typed() {
        let body = vec![
            Stmt::Var("c", index(var("counts"), var("t"))),
            Stmt::SetAt("c", count(2), rem(index(var("c"), count(3)), count(4))),
            Stmt::SetAt("counts", var("t") * count(2) / count(1), var("c")),
            Stmt::SetAt(
                "counts",
                count(0),
                counters([count(0), count(1), count(2), count(3)]),
            ),
            Stmt::SetAt("traj", var("t"), index(var("lanes"), var("t"))),
            perform("store", vec![var("t"), var("y")]),
            perform("clear", vec![var("t")]),
            Stmt::Let(
                "x",
                max(single(num(1.0)), single(index(var("y"), count(0)))),
            ),
        ];
        let program = with_buffers(body, var("x"));
        assert_eq!(result_type(&program), Ty::Single);
        assert!(program.function("clear").result_types(&program).is_empty());
    }

    #[test]
    #[should_panic(expected = "traj is a buffer: it is read at an index")]
    fn a_buffer_is_not_a_value() {
        result_type(&with_buffers(vec![Stmt::Let("all", var("traj"))], num(0.0)));
    }

    #[test]
    #[should_panic(expected = "lanes is a buffer the program only reads")]
    fn a_read_only_buffer_is_not_written() {
        let body = vec![Stmt::SetAt("lanes", count(0), num(1.0))];
        result_type(&with_buffers(body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "counts's new component")]
    fn a_buffer_holds_its_elements() {
        let body = vec![Stmt::SetAt("counts", count(0), count(1))];
        result_type(&with_buffers(body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "traj is declared twice")]
    fn a_buffer_is_not_shadowed() {
        result_type(&with_buffers(vec![Stmt::Let("traj", num(0.0))], num(0.0)));
    }

    #[test]
    #[should_panic(expected = "store has no result: it is called by a statement")]
    fn a_procedure_has_no_value() {
        let body = vec![Stmt::Let("z", apply("store", vec![var("t"), var("y")]))];
        result_type(&with_buffers(body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "clear has no result: it is called by a statement")]
    fn a_function_without_results_has_no_value() {
        let body = vec![Stmt::Let("z", call("clear", &["t"]))];
        result_type(&with_buffers(body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "f has results: they are used")]
    fn a_statement_calls_no_function_with_results() {
        let mut program = with_buffers(Vec::new(), num(0.0));
        program.functions.push(Function {
            name: "g",
            params: Vec::new(),
            body: vec![perform("f", vec![count(0), fill(num(0.0))])],
            results: Vec::new(),
            returns: None,
        });
        program.function("g").result_types(&program);
    }

    #[test]
    #[should_panic(expected = "a statement calls a function without results, not Num(1.0)")]
    fn a_statement_is_a_call() {
        result_type(&with_buffers(vec![Stmt::Do(num(1.0))], num(0.0)));
    }

    #[test]
    #[should_panic(expected = "store's argument")]
    fn a_procedure_takes_its_parameters_types() {
        let body = vec![perform("store", vec![var("t"), num(0.0)])];
        result_type(&with_buffers(body, num(0.0)));
    }

    #[test]
    #[should_panic(expected = "a single of Count")]
    fn a_single_is_made_of_a_number() {
        result_type(&one(vec![], vec![], single(count(1))));
    }

    #[test]
    #[should_panic(expected = "max of Real")]
    fn a_single_and_a_number_have_no_maximum() {
        result_type(&one(vec![], vec![], max(single(num(1.0)), num(2.0))));
    }

    #[test]
    #[should_panic(expected = "% is an operation of two counters")]
    fn a_number_has_no_remainder() {
        result_type(&one(vec![], vec![], rem(num(3.0), num(2.0))));
    }

    #[test]
    #[should_panic(expected = "four counters")]
    fn a_table_of_counters_has_four() {
        let e = Expr::Counters(vec![count(0), count(1), count(2)]);
        result_type(&one(vec![], vec![], e));
    }

    #[test]
    #[should_panic(expected = "four counters of Real")]
    fn a_table_of_counters_holds_counters() {
        let e = counters([count(0), count(1), count(2), num(3.0)]);
        result_type(&one(vec![], vec![], e));
    }
}
