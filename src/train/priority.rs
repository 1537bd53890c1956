//! Scheduling priority of training threads. In the viewer the trainer shares a few cores with
//! the UI and, on a machine without a GPU, with the software driver's render threads; at a lower
//! priority the trainer still takes every idle cycle, but a frame being drawn gets the CPU first.

/// Nice value for background training threads: at 5 the scheduler gives a competing nice-0
/// thread three quarters of a shared core, and training still moves while the view is busy
/// (at 10 a turntable view left it a tenth and the demo building stopped forming).
const BACKGROUND_NICE: i32 = 5;

/// Lowers the calling thread's scheduling priority (Linux; a no-op elsewhere). A thread that
/// already runs nicer (the whole app started under `nice -n 19`) keeps its priority: a
/// privileged process could otherwise raise it. A failure leaves the thread at its priority,
/// which only costs responsiveness, so it is not reported.
pub fn lower_current_thread_priority() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: getpriority and setpriority take plain integers and touch no memory of ours.
        // On Linux the nice value is per thread and `who = 0` names the calling thread.
        // getpriority returns the nice value itself (-20..=19); -1 on error is a valid value
        // too, and then the comparison below still only ever lowers the priority.
        unsafe {
            let current = libc::getpriority(libc::PRIO_PROCESS, 0);
            if current < BACKGROUND_NICE {
                libc::setpriority(libc::PRIO_PROCESS, 0, BACKGROUND_NICE);
            }
        }
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    #[test]
    fn lowers_only_the_calling_thread() {
        // SAFETY: getpriority takes plain integers; `who = 0` is the calling thread.
        let read = || unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) };
        let before = read();
        let lowered = std::thread::spawn(move || {
            super::lower_current_thread_priority();
            read()
        })
        .join()
        .expect("thread");
        assert_eq!(lowered, before.max(super::BACKGROUND_NICE));
        assert_eq!(read(), before, "the spawning thread keeps its priority");
    }
}
