//! Small file and machine helpers the benchmarks share: removing an output, comparing two files
//! byte for byte, the load average to print beside a timing.

use std::path::Path;
use std::process::Command;

/// Remove `path` if it exists.
pub fn remove(path: &Path) {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            panic!("remove {}: {e}", path.display())
        }
        _ => {}
    }
}

/// `cmp` of the two files: identical byte for byte (the first difference printed when not).
pub fn same_bytes(a: &Path, b: &Path) -> bool {
    let o = Command::new("cmp").arg(a).arg(b).output().expect("run cmp");
    if !o.status.success() {
        eprintln!(
            "cmp {} {}: {}{}",
            a.display(),
            b.display(),
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
    }
    o.status.success()
}

/// The 1-minute load average.
pub fn loadavg() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(f64::NAN)
}
