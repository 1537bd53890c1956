//! Learning-rate and SH-degree schedules of 3DGS, as pure functions of the (1-based) step.
//! No optimiser state here: Adam asks for the rates of a step and applies them.

/// 3DGS's `get_expon_lr_func`: log-linear interpolation from `init` to `final_` over
/// `max_steps`, optionally warmed up by a sine ramp from `delay_mult·lr` over `delay_steps`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExponentialLr {
    pub init: f32,
    pub final_: f32,
    pub delay_steps: u32,
    pub delay_mult: f32,
    pub max_steps: u32,
}

impl ExponentialLr {
    /// The rate at `step`; constant `final_` after `max_steps`.
    pub fn at(&self, step: u32) -> f32 {
        if self.init == 0.0 && self.final_ == 0.0 {
            return 0.0;
        }
        let delay = if self.delay_steps > 0 {
            let t = (step as f64 / self.delay_steps as f64).clamp(0.0, 1.0);
            let dm = self.delay_mult as f64;
            dm + (1.0 - dm) * (0.5 * std::f64::consts::PI * t).sin()
        } else {
            1.0
        };
        let t = if self.max_steps == 0 {
            1.0
        } else {
            (step as f64 / self.max_steps as f64).clamp(0.0, 1.0)
        };
        let log_lerp = ((self.init as f64).ln() * (1.0 - t) + (self.final_ as f64).ln() * t).exp();
        (delay * log_lerp) as f32
    }
}

/// Active SH degree at a 1-based step: 3DGS calls `oneupSHdegree` at every multiple of
/// `every` (1000), so degree `d` is active from step `d·every` on, capped at `max_degree`.
pub fn sh_degree_for_step(step: u32, max_degree: u32, every: u32) -> u32 {
    if every == 0 {
        return max_degree;
    }
    (step / every).min(max_degree)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_rate_decays_log_linearly_from_init_to_final() {
        let s = ExponentialLr {
            init: 1.6e-4,
            final_: 1.6e-6,
            delay_steps: 0,
            delay_mult: 0.01,
            max_steps: 30_000,
        };
        assert!((s.at(0) - 1.6e-4).abs() < 1e-10);
        // Halfway in log space: the geometric mean.
        assert!((s.at(15_000) - 1.6e-5).abs() < 1e-9, "{}", s.at(15_000));
        assert!((s.at(30_000) - 1.6e-6).abs() < 1e-11);
        assert_eq!(s.at(90_000), s.at(30_000));
    }

    #[test]
    fn delay_ramps_up_from_delay_mult() {
        let s = ExponentialLr {
            init: 1.0,
            final_: 1.0,
            delay_steps: 100,
            delay_mult: 0.1,
            max_steps: 1000,
        };
        assert!((s.at(0) - 0.1).abs() < 1e-6);
        assert!((s.at(100) - 1.0).abs() < 1e-6);
        assert!(s.at(50) > 0.1 && s.at(50) < 1.0);
    }

    #[test]
    fn sh_degree_rises_every_thousand_steps() {
        assert_eq!(sh_degree_for_step(1, 3, 1000), 0);
        assert_eq!(sh_degree_for_step(999, 3, 1000), 0);
        assert_eq!(sh_degree_for_step(1000, 3, 1000), 1);
        assert_eq!(sh_degree_for_step(3500, 3, 1000), 3);
        assert_eq!(sh_degree_for_step(9000, 2, 1000), 2);
    }
}
