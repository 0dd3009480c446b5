//! Closed loop of Tao & Kokotović (1995): a known LTI plant with an unknown input
//! backlash, the model-reference controller (3.2), an adaptive backlash inverse
//! ((2.7) exact, (2.6)/(2.8) filtered, (2.5)/(2.8) ramps, or the two comparisons of
//! Section IV) and the adaptive law (3.11) with projection and switching
//! sigma-modification.
//!
//! Numerics (identical to the NumPy reference `backlashkit._numpy_control`):
//! fixed-step RK4; the side of the inverse is a discrete mode switched where
//! `du_d/dt` crosses zero, the crossing located inside the step by Illinois regula
//! falsi on RK4 sub-steps (to 1e-12 of the step) and the step split there, so `v`
//! jumps at the located instant; the backlash is the play operator against its value
//! at the start of the step, updated at every accepted step end and on both sides of
//! every jump.

#![allow(clippy::needless_range_loop)] // small fixed-size numeric loops read best indexed

use crate::play::play_step;
use crate::Error;

/// A linear block `dx/dt = A x + b u`, `y = c x` (A row-major, q x q).
#[derive(Clone, Debug)]
pub struct Lti {
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub c: Vec<f64>,
}

impl Lti {
    fn order(&self) -> usize {
        self.b.len()
    }
    fn check(&self, name: &str, need_c: bool) -> Result<(), Error> {
        let q = self.b.len();
        if self.a.len() != q * q || (need_c && self.c.len() != q) {
            return Err(Error::InvalidArgument(format!(
                "{name}: A must be {q}x{q} and c of length {q}, got {} and {} entries",
                self.a.len(),
                self.c.len()
            )));
        }
        Ok(())
    }
}

/// The reference signal.
#[derive(Clone, Debug)]
pub enum Reference {
    /// `sum_i a_i sin(w_i t + phi_i)`.
    Sines {
        amps: Vec<f64>,
        freqs: Vec<f64>,
        phases: Vec<f64>,
    },
    /// Linear interpolation of a table, held at the ends (slope 0 outside).
    Table { t: Vec<f64>, r: Vec<f64> },
}

impl Reference {
    /// `(r, dr/dt)` at `t`.
    pub fn eval(&self, t: f64) -> (f64, f64) {
        match self {
            Reference::Sines {
                amps,
                freqs,
                phases,
            } => {
                let (mut r, mut rd) = (0.0, 0.0);
                for i in 0..amps.len() {
                    let arg = freqs[i] * t + phases[i];
                    r += amps[i] * arg.sin();
                    rd += amps[i] * freqs[i] * arg.cos();
                }
                (r, rd)
            }
            Reference::Table { t: tt, r: rr } => {
                let n = tt.len();
                if t <= tt[0] {
                    return (rr[0], 0.0);
                }
                if t >= tt[n - 1] {
                    return (rr[n - 1], 0.0);
                }
                let i = tt.partition_point(|&x| x <= t) - 1;
                let s = (rr[i + 1] - rr[i]) / (tt[i + 1] - tt[i]);
                (rr[i] + s * (t - tt[i]), s)
            }
        }
    }
}

/// Inverse variants (codes shared with the Python configuration objects).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InverseKind {
    /// `v = u_d`, no adaptation.
    None,
    /// (2.7): jumps between `u_d/m + c_r` and `u_d/m + c_l`.
    Exact,
    /// (2.6)/(2.8): `omega` filtered at `alpha`.
    SmoothFilter { alpha: f64 },
    /// (2.5)/(2.8): ramps of width `beta_r`, `beta_l` on `du_d/dt`.
    SmoothRamp { beta_r: f64, beta_l: f64 },
    /// `v = u_d / m_hat` (c_hat = 0).
    GainOnly,
}

impl InverseKind {
    /// From the integer code and two parameters used by the Python side.
    pub fn from_code(code: i64, p1: f64, p2: f64) -> Result<Self, Error> {
        let pos = |name: &str, x: f64| {
            if x.is_finite() && x > 0.0 {
                Ok(x)
            } else {
                Err(Error::InvalidArgument(format!(
                    "{name} must be finite and > 0, got {x}"
                )))
            }
        };
        Ok(match code {
            0 => InverseKind::None,
            1 => InverseKind::Exact,
            2 => InverseKind::SmoothFilter {
                alpha: pos("alpha", p1)?,
            },
            3 => InverseKind::SmoothRamp {
                beta_r: pos("beta_r", p1)?,
                beta_l: pos("beta_l", p2)?,
            },
            4 => InverseKind::GainOnly,
            _ => {
                return Err(Error::InvalidArgument(format!(
                    "unknown inverse code {code}, expected 0..=4"
                )))
            }
        })
    }
}

/// A closed-loop problem (see `backlashkit.control.closed_loop.build_problem`).
#[derive(Clone, Debug)]
pub struct AdaptiveProblem {
    pub plant: Lti,
    pub xp0: Vec<f64>,
    /// True backlash.
    pub m: f64,
    pub c_r: f64,
    pub c_l: f64,
    pub u0: f64,
    /// Controller filter `a(s)/Lambda(s)` (states = a(s)/Lambda [input]); its `c` is unused.
    pub filt: Lti,
    pub th1: Vec<f64>,
    pub th2: Vec<f64>,
    pub th3: f64,
    pub refmodel: Lti,
    pub hfilt: Lti,
    pub gamma: [f64; 3],
    pub sigma: f64,
    pub sigma_bound: f64,
    pub m0: f64,
    pub thb0: [f64; 3],
    pub kind: InverseKind,
    pub reference: Reference,
    pub h: f64,
    pub n_steps: usize,
    pub n_sub: usize,
    /// Output noise per integration step (empty: none).
    pub noise: Vec<f64>,
    /// Input disturbance per integration step (empty: none).
    pub dist: Vec<f64>,
}

/// Samples of a run, every `n_sub` steps.
#[derive(Clone, Debug, Default)]
pub struct AdaptiveOutput {
    pub t: Vec<f64>,
    pub r: Vec<f64>,
    pub y: Vec<f64>,
    pub ym: Vec<f64>,
    pub ud: Vec<f64>,
    pub v: Vec<f64>,
    pub u: Vec<f64>,
    /// Row-major (N x 3): `(mc_r, m, mc_l)` estimates.
    pub thb: Vec<f64>,
    /// Row-major (N x n_p): plant state.
    pub xp: Vec<f64>,
    pub n_switches: usize,
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `out = A x + b u`.
#[inline]
fn lti_rhs(l: &Lti, x: &[f64], u: f64, out: &mut [f64]) {
    let q = l.b.len();
    for i in 0..q {
        out[i] = dot(&l.a[i * q..(i + 1) * q], x) + l.b[i] * u;
    }
}

struct Layout {
    p: usize,
    x1: usize,
    x2: usize,
    xm: usize,
    z: usize,
    th: usize,
    w: usize,
    size: usize,
    np: usize,
    n: usize,
    q: usize,
    nh: usize,
}

struct Aux {
    y: f64,
    ud: f64,
    udd: f64,
    r: f64,
}

struct Loop<'a> {
    p: &'a AdaptiveProblem,
    l: Layout,
    tmp: Vec<f64>,
}

impl<'a> Loop<'a> {
    fn new(p: &'a AdaptiveProblem) -> Self {
        let (np, n, q, nh) = (
            p.plant.order(),
            p.filt.order(),
            p.refmodel.order(),
            p.hfilt.order(),
        );
        let mut o = 0;
        let pp = o;
        o += np;
        let x1 = o;
        o += n;
        let x2 = o;
        o += n;
        let xm = o;
        o += q;
        let z = o;
        o += 4 * nh;
        let th = o;
        o += 3;
        let w = o;
        let l = Layout {
            p: pp,
            x1,
            x2,
            xm,
            z,
            th,
            w,
            size: o + 1,
            np,
            n,
            q,
            nh,
        };
        let m = np.max(n).max(q).max(nh);
        Loop {
            p,
            l,
            tmp: vec![0.0; m],
        }
    }

    fn aux(&mut self, t: f64, x: &[f64], noise: f64) -> Aux {
        let p = self.p;
        let l = &self.l;
        let (r, rd) = p.reference.eval(t);
        let y = dot(&p.plant.c, &x[l.p..l.p + l.np]) + noise;
        let x1 = &x[l.x1..l.x1 + l.n];
        let x2 = &x[l.x2..l.x2 + l.n];
        let ud = dot(&p.th1, x1) + dot(&p.th2, x2) + p.th3 * r;
        let tmp = &mut self.tmp[..l.n];
        lti_rhs(&p.filt, x1, ud, tmp);
        let mut udd = dot(&p.th1, tmp);
        lti_rhs(&p.filt, x2, y, tmp);
        udd += dot(&p.th2, tmp) + p.th3 * rd;
        Aux { y, ud, udd, r }
    }

    fn inverse(&self, x: &[f64], ud: f64, udd: f64, mode: bool, lock: bool) -> f64 {
        let th = &x[self.l.th..self.l.th + 3];
        match self.p.kind {
            InverseKind::None => ud,
            InverseKind::GainOnly => ud / th[1],
            InverseKind::Exact => ud / th[1] + if mode { th[0] / th[1] } else { th[2] / th[1] },
            InverseKind::SmoothFilter { .. } => ud / th[1] + x[self.l.w],
            InverseKind::SmoothRamp { beta_r, beta_l } => {
                let (cr, cl) = (th[0] / th[1], th[2] / th[1]);
                let w = if lock {
                    if udd >= 0.0 {
                        cr
                    } else {
                        cr + (cr - cl) * (udd / beta_l).max(-1.0)
                    }
                } else if udd <= 0.0 {
                    cl
                } else {
                    cl + (cr - cl) * (udd / beta_r).min(1.0)
                };
                ud / th[1] + w
            }
        }
    }

    #[inline]
    fn play(&self, u_prev: f64, v: f64) -> f64 {
        play_step(u_prev, v, self.p.m, self.p.c_r, self.p.c_l)
    }

    #[allow(clippy::too_many_arguments)]
    fn deriv(
        &mut self,
        t: f64,
        x: &[f64],
        mode: bool,
        lock: bool,
        u_prev: f64,
        noise: f64,
        dist: f64,
        dx: &mut [f64],
    ) {
        let a = self.aux(t, x, noise);
        let p = self.p;
        let l = &self.l;
        let v = self.inverse(x, a.ud, a.udd, mode, lock);
        let u = self.play(u_prev, v) + dist;
        lti_rhs(&p.plant, &x[l.p..l.p + l.np], u, &mut dx[l.p..l.p + l.np]);
        lti_rhs(
            &p.filt,
            &x[l.x1..l.x1 + l.n],
            a.ud,
            &mut dx[l.x1..l.x1 + l.n],
        );
        lti_rhs(
            &p.filt,
            &x[l.x2..l.x2 + l.n],
            a.y,
            &mut dx[l.x2..l.x2 + l.n],
        );
        lti_rhs(
            &p.refmodel,
            &x[l.xm..l.xm + l.q],
            a.r,
            &mut dx[l.xm..l.xm + l.q],
        );
        let th = [x[l.th], x[l.th + 1], x[l.th + 2]];
        let chi = if mode { 1.0 } else { 0.0 };
        let wb = [chi, -v, 1.0 - chi];
        let tw = th[0] * wb[0] + th[1] * wb[1] + th[2] * wb[2];
        let mut zeta = [0.0; 3];
        let nh = l.nh;
        for j in 0..4 {
            let s = l.z + j * nh;
            let input = if j < 3 { wb[j] } else { tw };
            lti_rhs(&p.hfilt, &x[s..s + nh], input, &mut dx[s..s + nh]);
            if j < 3 {
                zeta[j] = dot(&p.hfilt.c, &x[s..s + nh]);
            }
        }
        if p.kind == InverseKind::None {
            dx[l.th..l.th + 3].fill(0.0);
        } else {
            let hpsi = dot(&p.hfilt.c, &x[l.z + 3 * nh..l.z + 4 * nh]);
            let e = a.y - dot(&p.refmodel.c, &x[l.xm..l.xm + l.q]);
            let xi = th[0] * zeta[0] + th[1] * zeta[1] + th[2] * zeta[2] - hpsi;
            let eps = e + xi;
            let nz = 1.0 + zeta[0] * zeta[0] + zeta[1] * zeta[1] + zeta[2] * zeta[2] + xi * xi;
            let mut dth = [0.0; 3];
            for i in 0..3 {
                dth[i] = -p.gamma[i] * zeta[i] * eps / nz;
            }
            if p.sigma > 0.0 {
                let nrm = (th[0] * th[0] + th[1] * th[1] + th[2] * th[2]).sqrt();
                let mb = p.sigma_bound;
                let ss = if nrm <= mb {
                    0.0
                } else if nrm <= 2.0 * mb {
                    p.sigma * (nrm / mb - 1.0)
                } else {
                    p.sigma
                };
                for i in 0..3 {
                    dth[i] -= ss * p.gamma[i] * th[i];
                }
            }
            if th[1] <= p.m0 && dth[1] < 0.0 {
                dth[1] = 0.0;
            }
            if th[0] <= 0.0 && dth[0] < 0.0 {
                dth[0] = 0.0;
            }
            if th[2] >= 0.0 && dth[2] > 0.0 {
                dth[2] = 0.0;
            }
            dx[l.th..l.th + 3].copy_from_slice(&dth);
        }
        dx[l.w] = match p.kind {
            InverseKind::SmoothFilter { alpha } => {
                let target = if mode { th[0] / th[1] } else { th[2] / th[1] };
                alpha * (target - x[l.w])
            }
            _ => 0.0,
        };
    }

    fn project(&self, x: &mut [f64]) {
        if self.p.kind == InverseKind::None {
            return;
        }
        let t = self.l.th;
        x[t + 1] = x[t + 1].max(self.p.m0);
        x[t] = x[t].max(0.0);
        x[t + 2] = x[t + 2].min(0.0);
    }
}

struct Rk4Buf {
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    xs: Vec<f64>,
}

#[allow(clippy::too_many_arguments)]
fn rk4(
    lp: &mut Loop,
    b: &mut Rk4Buf,
    t: f64,
    x: &[f64],
    h: f64,
    mode: bool,
    lock: bool,
    u_prev: f64,
    noise: f64,
    dist: f64,
    out: &mut [f64],
) {
    let n = x.len();
    lp.deriv(t, x, mode, lock, u_prev, noise, dist, &mut b.k1);
    for i in 0..n {
        b.xs[i] = x[i] + 0.5 * h * b.k1[i];
    }
    lp.deriv(
        t + 0.5 * h,
        &b.xs,
        mode,
        lock,
        u_prev,
        noise,
        dist,
        &mut b.k2,
    );
    for i in 0..n {
        b.xs[i] = x[i] + 0.5 * h * b.k2[i];
    }
    lp.deriv(
        t + 0.5 * h,
        &b.xs,
        mode,
        lock,
        u_prev,
        noise,
        dist,
        &mut b.k3,
    );
    for i in 0..n {
        b.xs[i] = x[i] + h * b.k3[i];
    }
    lp.deriv(t + h, &b.xs, mode, lock, u_prev, noise, dist, &mut b.k4);
    for i in 0..n {
        out[i] = x[i] + h / 6.0 * (b.k1[i] + 2.0 * b.k2[i] + 2.0 * b.k3[i] + b.k4[i]);
    }
    lp.project(out);
}

#[inline]
fn wrong_side(mode: bool, g: f64) -> bool {
    (mode && g < 0.0) || (!mode && g > 0.0)
}

fn validate(p: &AdaptiveProblem) -> Result<(), Error> {
    p.plant.check("plant", true)?;
    p.filt.check("filter", false)?;
    p.refmodel.check("reference model", true)?;
    p.hfilt.check("H filter", true)?;
    let n = p.filt.order();
    if p.th1.len() != n || p.th2.len() != n {
        return Err(Error::InvalidArgument(format!(
            "theta_1 and theta_2 must have {n} entries"
        )));
    }
    if p.xp0.len() != p.plant.order() {
        return Err(Error::InvalidArgument(
            "xp0 must have one entry per plant state".into(),
        ));
    }
    if !(p.h.is_finite() && p.h > 0.0) || p.n_sub == 0 {
        return Err(Error::InvalidArgument(format!(
            "step h must be > 0 and n_sub >= 1, got h={} n_sub={}",
            p.h, p.n_sub
        )));
    }
    if !(p.m > 0.0 && p.c_l < p.c_r) {
        return Err(Error::InvalidArgument(
            "backlash needs m > 0 and c_l < c_r".into(),
        ));
    }
    if !(p.m0 > 0.0 && p.thb0[1] >= p.m0) {
        return Err(Error::InvalidArgument(
            "need m0 > 0 and theta_b0[1] >= m0".into(),
        ));
    }
    if p.sigma_bound.is_nan() || p.sigma_bound <= 0.0 {
        return Err(Error::InvalidArgument("sigma_bound must be > 0".into()));
    }
    match &p.reference {
        Reference::Sines {
            amps,
            freqs,
            phases,
        } => {
            if amps.len() != freqs.len() || amps.len() != phases.len() {
                return Err(Error::InvalidArgument(
                    "amplitude, frequency, phase lengths differ".into(),
                ));
            }
        }
        Reference::Table { t, r } => {
            if t.len() < 2 || t.len() != r.len() || t.windows(2).any(|w| w[1] <= w[0]) {
                return Err(Error::InvalidArgument(
                    "reference table needs >= 2 increasing times".into(),
                ));
            }
        }
    }
    Ok(())
}

/// Simulate the closed loop; output every `n_sub` steps (`n_steps / n_sub + 1` rows).
pub fn simulate_adaptive(p: &AdaptiveProblem) -> Result<AdaptiveOutput, Error> {
    validate(p)?;
    let mut lp = Loop::new(p);
    let size = lp.l.size;
    let (h, n_steps, n_sub) = (p.h, p.n_steps, p.n_sub);
    let mut x = vec![0.0; size];
    x[lp.l.p..lp.l.p + lp.l.np].copy_from_slice(&p.xp0);
    x[lp.l.th..lp.l.th + 3].copy_from_slice(&p.thb0);
    let noise_at = |k: usize| p.noise.get(k).copied().unwrap_or(0.0);
    let dist_at = |k: usize| p.dist.get(k).copied().unwrap_or(0.0);
    let a0 = lp.aux(0.0, &x, noise_at(0));
    let mut mode = a0.udd >= 0.0;
    let mut lock = mode;
    if let InverseKind::SmoothFilter { .. } = p.kind {
        let th = lp.l.th;
        x[lp.l.w] = if mode {
            x[th] / x[th + 1]
        } else {
            x[th + 2] / x[th + 1]
        };
    }
    let mut u_prev = p.u0;
    let mut n_sw = 0usize;
    let n_out = n_steps / n_sub + 1;
    let mut out = AdaptiveOutput::default();
    for v in [
        &mut out.t,
        &mut out.r,
        &mut out.y,
        &mut out.ym,
        &mut out.ud,
        &mut out.v,
        &mut out.u,
    ] {
        v.reserve(n_out);
    }
    out.thb.reserve(3 * n_out);
    let mut buf = Rk4Buf {
        k1: vec![0.0; size],
        k2: vec![0.0; size],
        k3: vec![0.0; size],
        k4: vec![0.0; size],
        xs: vec![0.0; size],
    };
    let mut xn = vec![0.0; size];
    let mut xs = vec![0.0; size];
    let mut t = 0.0;
    for k in 0..=n_steps {
        let (noise, dist) = (noise_at(k), dist_at(k));
        let a = lp.aux(t, &x, noise);
        if wrong_side(mode, a.udd) {
            u_prev = lp.play(u_prev, lp.inverse(&x, a.ud, a.udd, mode, lock));
            mode = !mode;
            n_sw += 1;
        }
        let v = lp.inverse(&x, a.ud, a.udd, mode, lock);
        u_prev = lp.play(u_prev, v);
        if let InverseKind::SmoothRamp { beta_r, beta_l } = p.kind {
            if a.udd >= beta_r {
                lock = true;
            } else if a.udd <= -beta_l {
                lock = false;
            }
        }
        if k % n_sub == 0 {
            let l = &lp.l;
            out.t.push(t);
            out.r.push(a.r);
            out.y.push(dot(&p.plant.c, &x[l.p..l.p + l.np]));
            out.ym.push(dot(&p.refmodel.c, &x[l.xm..l.xm + l.q]));
            out.ud.push(a.ud);
            out.v.push(v);
            out.u.push(u_prev + dist);
            out.thb.extend_from_slice(&x[l.th..l.th + 3]);
            out.xp.extend_from_slice(&x[l.p..l.p + l.np]);
            if !x.iter().all(|z| z.is_finite()) {
                return Err(Error::Diverged { time: t });
            }
        }
        if k == n_steps {
            break;
        }
        let t_end = (k + 1) as f64 * h;
        let mut remaining = h;
        let mut done = false;
        for _ in 0..8 {
            rk4(
                &mut lp, &mut buf, t, &x, remaining, mode, lock, u_prev, noise, dist, &mut xn,
            );
            let an = lp.aux(t + remaining, &xn, noise);
            if !wrong_side(mode, an.udd) {
                std::mem::swap(&mut x, &mut xn);
                t = t_end;
                done = true;
                break;
            }
            // locate the zero of du_d/dt in (0, remaining): Illinois regula falsi
            let g0 = lp.aux(t, &x, noise).udd;
            let (mut lo, mut flo, mut hi, mut fhi) = (0.0, g0, remaining, an.udd);
            let mut side = 0i8;
            for _ in 0..60 {
                let mut s = if fhi != flo {
                    (lo * fhi - hi * flo) / (fhi - flo)
                } else {
                    0.5 * (lo + hi)
                };
                if !(lo < s && s < hi) {
                    s = 0.5 * (lo + hi);
                }
                rk4(
                    &mut lp, &mut buf, t, &x, s, mode, lock, u_prev, noise, dist, &mut xs,
                );
                let fs = lp.aux(t + s, &xs, noise).udd;
                if wrong_side(mode, fs) {
                    hi = s;
                    fhi = fs;
                    if side == -1 {
                        flo *= 0.5;
                    }
                    side = -1;
                } else {
                    lo = s;
                    flo = fs;
                    if side == 1 {
                        fhi *= 0.5;
                    }
                    side = 1;
                }
                if hi - lo <= 1e-12 * h {
                    break;
                }
            }
            rk4(
                &mut lp, &mut buf, t, &x, hi, mode, lock, u_prev, noise, dist, &mut xs,
            );
            t += hi;
            std::mem::swap(&mut x, &mut xs);
            let a_s = lp.aux(t, &x, noise);
            u_prev = lp.play(u_prev, lp.inverse(&x, a_s.ud, a_s.udd, mode, lock));
            mode = !mode;
            n_sw += 1;
            u_prev = lp.play(u_prev, lp.inverse(&x, a_s.ud, a_s.udd, mode, lock));
            remaining = t_end - t;
            if remaining <= 1e-12 * h {
                t = t_end;
                done = true;
                break;
            }
        }
        if !done {
            t = t_end;
        }
        let ae = lp.aux(t, &x, noise);
        u_prev = lp.play(u_prev, lp.inverse(&x, ae.ud, ae.udd, mode, lock));
    }
    out.n_switches = n_sw;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Paper B's example with the true backlash known exactly (theta_b(0) = theta_b*,
    /// tiny gains): the exact inverse cancels the backlash, so y tracks y_m.
    fn paper_problem(kind: InverseKind, thb0: [f64; 3], duration: f64) -> AdaptiveProblem {
        // G = 1/(s^2 - 0.5 s - 1.5) in companion form; Lambda = (s+2)^2; R_m = (s+2)(s+3)
        let plant = Lti {
            a: vec![0.0, 1.0, 1.5, 0.5],
            b: vec![0.0, 1.0],
            c: vec![1.0, 0.0],
        };
        let filt = Lti {
            a: vec![0.0, 1.0, -4.0, -4.0],
            b: vec![0.0, 1.0],
            c: vec![1.0, 0.0],
        };
        let refmodel = Lti {
            a: vec![0.0, 1.0, -6.0, -5.0],
            b: vec![0.0, 1.0],
            c: vec![1.0, 0.0],
        };
        // H = (s^2 + 9.5 s + 36.25) / ((s+2)^2 (s+2)(s+3)) = ... / (s^4 + 9 s^3 + 30 s^2 + 44 s + 24)
        let hfilt = Lti {
            a: vec![
                0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, -24.0, -44.0, -30.0,
                -9.0,
            ],
            b: vec![0.0, 0.0, 0.0, 1.0],
            c: vec![36.25, 9.5, 1.0, 0.0],
        };
        let h = 1e-3;
        AdaptiveProblem {
            plant,
            xp0: vec![0.0, 0.0],
            m: 0.7,
            c_r: 1.3,
            c_l: -0.5,
            u0: 0.0,
            filt,
            th1: vec![-32.25, -5.5],
            th2: vec![-78.375, -76.375],
            th3: 1.0,
            refmodel,
            hfilt,
            gamma: [5.0; 3],
            sigma: 0.0,
            sigma_bound: 10.0,
            m0: 0.02,
            thb0,
            kind,
            reference: Reference::Sines {
                amps: vec![10.0],
                freqs: vec![1.3],
                phases: vec![0.0],
            },
            h,
            n_steps: (duration / h).round() as usize,
            n_sub: 10,
            noise: vec![],
            dist: vec![],
        }
    }

    #[test]
    fn exact_inverse_with_true_parameters_tracks() {
        let p = paper_problem(InverseKind::Exact, [0.91, 0.7, -0.35], 10.0);
        let out = simulate_adaptive(&p).unwrap();
        let emax = out
            .y
            .iter()
            .zip(&out.ym)
            .skip(200)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(emax < 1e-3, "max |e| = {emax}");
        assert!(out.n_switches >= 4);
    }

    #[test]
    fn fixed_controller_does_not_track() {
        let p = paper_problem(InverseKind::None, [0.91, 0.7, -0.35], 10.0);
        let out = simulate_adaptive(&p).unwrap();
        let emax = out
            .y
            .iter()
            .zip(&out.ym)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(emax > 0.1, "max |e| = {emax}");
    }

    #[test]
    fn rejects_bad_problem() {
        let mut p = paper_problem(InverseKind::Exact, [0.91, 0.7, -0.35], 1.0);
        p.h = 0.0;
        assert!(simulate_adaptive(&p).is_err());
        assert!(InverseKind::from_code(9, 0.0, 0.0).is_err());
        assert!(InverseKind::from_code(2, -1.0, 0.0).is_err());
    }
}
