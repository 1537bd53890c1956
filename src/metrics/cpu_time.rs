//! The process's CPU time, the cost figure that stays honest on a shared host: wall time grows
//! with other processes' load, user + system seconds hardly do.

use std::time::Instant;

/// User + system CPU seconds of the whole process (every thread) so far, from `getrusage`;
/// `None` where the call fails.
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn busy_work_counts_as_cpu_time_and_sleep_does_not() {
        if !cfg!(target_os = "linux") {
            return;
        }
        let clock = PhaseClock::start();
        std::thread::sleep(std::time::Duration::from_millis(150));
        let slept = clock.cpu_seconds().expect("getrusage works on Linux");
        assert!(slept < 0.1, "sleeping cost {slept} CPU s");
        let clock = PhaseClock::start();
        let mut x = 1u64;
        while clock.wall_seconds() < 0.15 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
        let busy = clock.cpu_seconds().expect("getrusage works on Linux");
        // On a loaded host the thread may get only part of a core: a third is still far above
        // the sleep's few milliseconds.
        assert!(busy > 0.05, "spinning 150 ms cost {busy} CPU s");
    }
}
