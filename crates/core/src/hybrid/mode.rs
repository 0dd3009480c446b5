//! A mode as the engine uses it: its flow over one internal step, its guard functions
//! normalised and with their slopes, the same in fixed-width lanes for the per-sample
//! check, and the cache of the modes built so far.

use std::cell::OnceCell;
use std::collections::HashMap;

use super::settle::Modal;
use super::HybridModel;
use crate::linalg::{dot, expm_and_integral, matvec, vecmat, Mat, Vector};

#[derive(Clone, Debug)]
pub(super) struct FuncData<const S: usize> {
    pub(super) h: Vector<S>,
    pub(super) hu: f64,
    pub(super) d: f64,
    /// Time derivative along the flow: `g' = ha.x + hb u + hc`.
    pub(super) ha: Vector<S>,
    pub(super) hb: f64,
    pub(super) hc: f64,
}

#[derive(Clone, Debug)]
pub(super) struct GuardData {
    pub(super) funcs: std::ops::Range<usize>,
    pub(super) index: usize,
    pub(super) target: i8,
}

/// A mode built for the engine: `dx/dt = A x + b u + c`, its exact flow over one
/// internal step, `x <- E x + fb u + fc`, and its guards (functions normalised by their
/// scales, with their slopes along the flow).
#[derive(Clone, Debug)]
pub(super) struct ModeData<const S: usize, const W: usize> {
    pub(super) a: Mat<S>,
    pub(super) b: Vector<S>,
    pub(super) c: Vector<S>,
    pub(super) e: Mat<S>,
    pub(super) fb: Vector<S>,
    pub(super) fc: Vector<S>,
    pub(super) funcs: Vec<FuncData<S>>,
    pub(super) guards: Vec<GuardData>,
    pub(super) fast: FastGuards<S, W>,
    /// The modal form for settling (`settle`), built on the first try.
    pub(super) modal: OnceCell<Option<Modal<S>>>,
}

impl<const S: usize, const W: usize> ModeData<S, W> {
    /// The mode `modes` of `model` for the internal step `h`.
    pub(super) fn new<M: HybridModel<S>>(model: &M, modes: &[i8], h: f64) -> Self {
        let (a, b, c) = model.dynamics(modes);
        let (e, f) = expm_and_integral(&a, h);
        let mut funcs = Vec::new();
        let mut guards = Vec::new();
        for spec in model.guards(modes) {
            let start = funcs.len();
            for g in spec.funcs {
                // Normalise by the scale so that the functions of a guard compare, and
                // tolerances and margins are relative.
                let mut h = g.h;
                h.iter_mut().for_each(|v| *v /= g.scale);
                funcs.push(FuncData {
                    ha: vecmat(&h, &a),
                    hb: dot(&h, &b),
                    hc: dot(&h, &c),
                    h,
                    hu: g.hu / g.scale,
                    d: g.d / g.scale,
                });
            }
            guards.push(GuardData {
                funcs: start..funcs.len(),
                index: spec.index,
                target: spec.target,
            });
        }
        let fast = FastGuards::new(&funcs, &guards);
        ModeData {
            a,
            b,
            c,
            fb: matvec(&f, &b),
            fc: matvec(&f, &c),
            e,
            funcs,
            guards,
            fast,
            modal: OnceCell::new(),
        }
    }
}

/// The guard functions of a mode in fixed-width struct-of-arrays form for the
/// per-sample check: `W` lanes (4 per shaft), unused lanes padded so they never fire.
/// Fixed widths let the compiler unroll and vectorise the check.
#[derive(Clone, Debug)]
pub(super) struct FastGuards<const S: usize, const W: usize> {
    pub(super) h: [Vector<S>; W],
    pub(super) hu: [f64; W],
    pub(super) d: [f64; W],
    pub(super) ha: [Vector<S>; W],
    pub(super) hb: [f64; W],
    pub(super) hc: [f64; W],
    /// Lanes of each guard (bit i = lane i); unused entries hold a bit no lane sets.
    pub(super) lanes: [u64; W],
    /// Whether the input enters some value or slope (`hu != 0` or `hb != 0`).
    pub(super) input_enters: bool,
}

/// Largest number of lanes: one bit of a `u64` mask each, and one spare bit.
const MAX_LANES: usize = 60;
/// A lane mask bit that no lane sets (W <= MAX_LANES), so an unused guard never fires.
const NEVER: u64 = 1 << 63;

impl<const S: usize, const W: usize> FastGuards<S, W> {
    fn new(funcs: &[FuncData<S>], guards: &[GuardData]) -> Self {
        assert!(
            funcs.len() <= W && guards.len() <= W && W <= MAX_LANES,
            "too many guard functions"
        );
        let mut fg = FastGuards {
            h: [[0.0; S]; W],
            hu: [0.0; W],
            d: [-1.0; W],
            ha: [[0.0; S]; W],
            hb: [0.0; W],
            hc: [0.0; W],
            lanes: [NEVER; W],
            input_enters: funcs.iter().any(|f| f.hb != 0.0 || f.hu != 0.0),
        };
        for (i, f) in funcs.iter().enumerate() {
            (fg.h[i], fg.hu[i], fg.d[i]) = (f.h, f.hu, f.d);
            (fg.ha[i], fg.hb[i], fg.hc[i]) = (f.ha, f.hb, f.hc);
        }
        for (gi, g) in guards.iter().enumerate() {
            fg.lanes[gi] = g.funcs.clone().fold(0, |m, i| m | (1 << i));
        }
        fg
    }
}

/// Most values a switch's mode code takes (`-2..=2`).
pub(super) const MODE_CODES: usize = 5;

/// The modes as one number in base `codes` (codes `-(codes / 2) ..= codes / 2`).
pub(super) fn encode(modes: &[i8], codes: usize) -> usize {
    let offset = (codes / 2) as i8;
    modes
        .iter()
        .rev()
        .fold(0usize, |acc, &m| acc * codes + (m + offset) as usize)
}

/// Most mode codes for which the cache is a dense table (one pointer per code); larger
/// mode spaces (many friction switches) use a hash map.
const DENSE_MODES: usize = 1 << 12;

/// Built modes by code: a dense table where the mode space is small (a plain index on
/// the hot path), a hash map where it is not.
pub(super) enum ModeCache<const S: usize, const W: usize> {
    Dense(Vec<Option<Box<ModeData<S, W>>>>),
    Sparse(HashMap<usize, Box<ModeData<S, W>>>),
}

impl<const S: usize, const W: usize> ModeCache<S, W> {
    pub(super) fn new(n_codes: usize) -> Self {
        if n_codes <= DENSE_MODES {
            ModeCache::Dense((0..n_codes).map(|_| None).collect())
        } else {
            ModeCache::Sparse(HashMap::new())
        }
    }

    #[inline(always)]
    pub(super) fn get(&self, id: usize) -> Option<&ModeData<S, W>> {
        match self {
            ModeCache::Dense(v) => v[id].as_deref(),
            ModeCache::Sparse(m) => m.get(&id).map(|b| b.as_ref()),
        }
    }

    pub(super) fn insert(&mut self, id: usize, md: Box<ModeData<S, W>>) {
        match self {
            ModeCache::Dense(v) => v[id] = Some(md),
            ModeCache::Sparse(m) => {
                m.insert(id, md);
            }
        }
    }
}
