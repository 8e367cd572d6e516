//! The server process's own footprint — resident memory, its peak and
//! thread count — read from `/proc/self/status` at scrape time, so a load
//! test can check memory against the cache bound and spot thread
//! oversubscription. Other platforms report nothing.

/// What the kernel says about this process.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProcessStats {
    /// Resident set size, bytes (`VmRSS`).
    pub resident_bytes: u64,
    /// Peak resident set size, bytes (`VmHWM`).
    pub peak_resident_bytes: u64,
    /// Threads (`Threads`).
    pub threads: u64,
}

/// This process's stats, or `None` where `/proc` is unavailable.
pub fn current() -> Option<ProcessStats> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    parse_status(&text)
}

/// Parses the text of a `/proc/PID/status` file.
pub fn parse_status(text: &str) -> Option<ProcessStats> {
    let mut s = ProcessStats::default();
    let mut found = 0;
    for line in text.lines() {
        let Some((key, rest)) = line.split_once(':') else {
            continue;
        };
        let mut words = rest.split_whitespace();
        let value: u64 = match words.next().and_then(|v| v.parse().ok()) {
            Some(v) => v,
            None => continue,
        };
        // Memory lines are in kB (the kernel's kibibytes).
        let bytes = match words.next() {
            Some("kB") => value * 1024,
            _ => value,
        };
        match key {
            "VmRSS" => s.resident_bytes = bytes,
            "VmHWM" => s.peak_resident_bytes = bytes,
            "Threads" => s.threads = value,
            _ => continue,
        }
        found += 1;
    }
    (found > 0).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_kernel_format() {
        let text = "Name:\tsolidtex\nVmHWM:\t  204800 kB\nVmRSS:\t  102400 kB\nThreads:\t9\n";
        let s = parse_status(text).unwrap();
        assert_eq!(s.resident_bytes, 100 << 20);
        assert_eq!(s.peak_resident_bytes, 200 << 20);
        assert_eq!(s.threads, 9);
        assert_eq!(parse_status("Name:\tx\n"), None);
    }

    #[test]
    fn reads_this_process_on_linux() {
        if cfg!(target_os = "linux") {
            let s = current().unwrap();
            assert!(s.resident_bytes > 0);
            assert!(s.peak_resident_bytes >= s.resident_bytes);
            assert!(s.threads >= 1);
        }
    }
}
