//! Coulomb and static friction of the chain's inertias: stick-slip as modes.
//!
//! An inertia with a breakaway torque `fs > 0` has a switch: `+1` / `-1` while it
//! slips forwards / backwards (Coulomb torque `-+fc`), `0` while it sticks (its speed
//! row is zero). A slipping inertia leaves its mode when its speed crosses zero; it
//! then sticks if the torque on it (input and shafts, friction excluded) is within
//! `[-fs, fs]`, else slips the other way. A stuck inertia breaks away when that torque
//! exceeds `fs` in magnitude. The torque is affine in state and input, so every mode
//! stays linear and every guard affine.

use super::model::{negate, ChainModel};
use crate::hybrid::{GuardFn, GuardSpec};
use crate::linalg::{dot, Vector};

impl<const S: usize> ChainModel<S> {
    /// Torque on inertia `i` from the input and the shafts in contact modes `contact`
    /// (friction excluded), as an affine function of state and input.
    fn drive_torque_fn(&self, i: usize, contact: &[i8]) -> GuardFn<S> {
        let (a, b, c) = self.free_dynamics(contact, false);
        let ji = self.p.j[i];
        let mut h = a[i];
        h.iter_mut().for_each(|v| *v *= ji);
        GuardFn {
            h,
            hu: b[i] * ji,
            d: c[i] * ji,
            scale: self.p.breakaway(i),
        }
    }

    fn drive_torque(&self, i: usize, contact: &[i8], x: &Vector<S>, u: f64) -> f64 {
        let g = self.drive_torque_fn(i, contact);
        dot(&g.h, x) + g.hu * u + g.d
    }

    /// Guards of friction switch `r` (inertia `sticky[r]`) in mode `m`.
    pub(super) fn friction_guards(
        &self,
        r: usize,
        m: i8,
        contact: &[i8],
        out: &mut Vec<GuardSpec<S>>,
    ) {
        let i = self.sticky[r];
        let index = self.n - 1 + r;
        if m == 0 {
            let fs = self.p.breakaway(i);
            let mut up = self.drive_torque_fn(i, contact);
            up.d -= fs;
            let mut down = negate(self.drive_torque_fn(i, contact));
            down.d -= fs;
            out.push(GuardSpec {
                funcs: vec![up],
                index,
                target: 1,
            });
            out.push(GuardSpec {
                funcs: vec![down],
                index,
                target: -1,
            });
            return;
        }
        // The speed crosses zero against the direction of slip.
        let mut h = [0.0; S];
        h[i] = -(m as f64);
        let speed_scale = self.p.breakaway(i) * self.ts / self.p.j[i];
        out.push(GuardSpec {
            funcs: vec![GuardFn {
                h,
                hu: 0.0,
                d: 0.0,
                scale: speed_scale,
            }],
            index,
            target: 0,
        });
    }

    /// Initial mode of friction switch `r`: the direction of motion, or stuck when at
    /// rest with the torque within the breakaway torque.
    pub(super) fn classify_friction(&self, r: usize, contact: &[i8], x: &Vector<S>, u: f64) -> i8 {
        let i = self.sticky[r];
        if x[i] != 0.0 {
            return if x[i] > 0.0 { 1 } else { -1 };
        }
        self.stick_or_slip(i, contact, x, u)
    }

    fn stick_or_slip(&self, i: usize, contact: &[i8], x: &Vector<S>, u: f64) -> i8 {
        let torque = self.drive_torque(i, contact, x, u);
        let fs = self.p.breakaway(i);
        if torque > fs {
            1
        } else if torque < -fs {
            -1
        } else {
            0
        }
    }

    /// The mode taken when a guard of friction switch `r` fires at `x`: after a zero
    /// crossing of the speed, stuck (the speed set to exactly 0) or slipping the other
    /// way; a breakaway keeps its direction.
    pub(super) fn resolve_friction(
        &self,
        r: usize,
        target: i8,
        modes: &[i8],
        x: &mut Vector<S>,
        u: f64,
    ) -> i8 {
        if target != 0 {
            return target;
        }
        let i = self.sticky[r];
        x[i] = 0.0;
        self.stick_or_slip(i, &modes[..self.n - 1], x, u)
    }
}
