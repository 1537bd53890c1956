//! The process's CPU time, the cost figure that stays honest on a shared host: wall time grows
//! with other processes' load, user + system seconds hardly do.

use std::time::Instant;

/// User + system CPU seconds of the whole process (every thread) so far, from `getrusage`;
/// `None` where the call fails.
#[cfg(unix)]
pub fn process_cpu_seconds() -> Option<f64> {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: `getrusage` writes one `rusage` into the pointer it is given, which points to a
    // zeroed, properly aligned `rusage` that lives across the call; RUSAGE_SELF is valid.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) };
    if rc != 0 {
        return None;
    }
    // SAFETY: the call succeeded, so it filled the struct (it was zeroed before in any case).
    let usage = unsafe { usage.assume_init() };
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some(seconds(usage.ru_utime) + seconds(usage.ru_stime))
}

/// No `getrusage` off Unix: the CPU figures are left empty there.
#[cfg(not(unix))]
pub fn process_cpu_seconds() -> Option<f64> {
    None
}

/// Wall and CPU time since it was started: one phase of a run.
#[derive(Clone, Copy, Debug)]
pub struct PhaseClock {
    wall: Instant,
    cpu: Option<f64>,
}

impl PhaseClock {
    pub fn start() -> PhaseClock {
        PhaseClock {
            wall: Instant::now(),
            cpu: process_cpu_seconds(),
        }
    }

    pub fn wall_seconds(&self) -> f64 {
        self.wall.elapsed().as_secs_f64()
    }

    /// The process's CPU seconds since the start (all threads); `None` when unavailable.
    pub fn cpu_seconds(&self) -> Option<f64> {
        Some(process_cpu_seconds()? - self.cpu?)
    }
}

/// Wall and CPU seconds per phase of a run, each phase a field of `P` (a struct of seconds).
#[derive(Clone, Debug)]
pub struct PhaseTimes<P> {
    pub wall: P,
    /// Stays Some while every phase's CPU time could be read.
    pub cpu: Option<P>,
}

impl<P: Default> PhaseTimes<P> {
    pub fn new() -> PhaseTimes<P> {
        PhaseTimes {
            wall: P::default(),
            cpu: Some(P::default()),
        }
    }

    /// Writes `clock`'s wall and CPU seconds into the phase `field`, giving up on CPU times
    /// (None) when they cannot be read.
    pub fn record(&mut self, clock: &PhaseClock, field: fn(&mut P) -> &mut f64) {
        *field(&mut self.wall) = clock.wall_seconds();
        self.cpu = self.cpu.take().and_then(|mut phases| {
            *field(&mut phases) = clock.cpu_seconds()?;
            Some(phases)
        });
    }
}

impl<P: Default> Default for PhaseTimes<P> {
    fn default() -> Self {
        PhaseTimes::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn busy_work_counts_as_cpu_time() {
        if !cfg!(target_os = "linux") {
            return;
        }
        let clock = PhaseClock::start();
        assert!(clock.cpu_seconds().expect("getrusage works on Linux") >= 0.0);
        // Spin until the process has spent 50 ms of CPU: on a loaded host the thread gets only
        // part of a core, so wait on CPU time, with a wall-clock limit that fails a clock that
        // never moves. (Other tests' threads count too; they only make it sooner.)
        let mut x = 1u64;
        while clock.cpu_seconds().unwrap_or(0.0) < 0.05 && clock.wall_seconds() < 60.0 {
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        }
        let busy = clock.cpu_seconds().unwrap_or(0.0);
        assert!(busy >= 0.05, "a minute of spinning counted {busy} CPU s");
        // The counter goes on: seconds are user + system of the whole process, not a reset.
        assert!(process_cpu_seconds().unwrap_or(0.0) >= busy);
    }
}
