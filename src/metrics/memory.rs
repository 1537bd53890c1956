//! The process's peak resident memory, as the benchmarks report it.

/// Peak resident set size in MiB (`VmHWM` from /proc/self/status on Linux); `None` elsewhere or
/// when the kernel does not report it.
pub fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

#[cfg(test)]
mod tests {
    #[test]
    fn peak_rss_is_positive_on_linux() {
        if cfg!(target_os = "linux") {
            let mb = super::peak_rss_mb().expect("VmHWM readable on Linux");
            assert!(mb > 0.1 && mb < 1.0e6, "{mb}");
        }
    }
}
