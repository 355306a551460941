//! Memory ceilings: a request whose buffers would not fit is refused before anything is
//! allocated, naming what asked for them, the estimate and the limit, rather than ending in an
//! allocation failure (an abort that names nothing).
//!
//! The limit is `--memory-limit` where a command has it, else `PHI_MEMORY_LIMIT` (a size such as
//! `8G`, see [`parse_bytes`]), else the machine's memory.

use anyhow::{Context, Result, bail};

/// The machine's total memory in bytes (`MemTotal` of `/proc/meminfo`), `None` where it cannot
/// be read (then no ceiling applies unless one is given).
pub(crate) fn machine_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let mut words = line.split_whitespace().skip(1);
    let value: u64 = words.next()?.parse().ok()?;
    let factor = match words.next() {
        Some("kB") => 1024,
        Some("B") | None => 1,
        Some(_) => return None,
    };
    value.checked_mul(factor).filter(|&m| m > 0)
}

/// Parses a size in bytes: a number with an optional unit, `B`, `K`/`KiB`, `M`/`MiB`,
/// `G`/`GiB`, `T`/`TiB` (binary units; `KB`, `MB`, `GB`, `TB` are decimal).
///
/// # Errors
/// Text that is not a positive size.
pub fn parse_bytes(text: &str) -> Result<u64> {
    let trimmed = text.trim();
    let split = trimmed
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == 'E'))
        .unwrap_or(trimmed.len());
    let (number, unit) = trimmed.split_at(split);
    let factor: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kib" => 1024.0,
        "m" | "mib" => 1024f64.powi(2),
        "g" | "gib" => 1024f64.powi(3),
        "t" | "tib" => 1024f64.powi(4),
        "kb" => 1e3,
        "mb" => 1e6,
        "gb" => 1e9,
        "tb" => 1e12,
        other => bail!("unknown unit {other:?} in the size {text:?}; use B, KiB, MiB, GiB or TiB"),
    };
    let value: f64 = number
        .parse()
        .map_err(|_| anyhow::anyhow!("{text:?} is not a size (e.g. 512MiB, 8GiB, 1e9)"))?;
    let bytes = value * factor;
    if !(bytes.is_finite() && bytes >= 1.0 && bytes < u64::MAX as f64) {
        bail!("the size {text:?} must be at least one byte and finite");
    }
    Ok(bytes as u64)
}

/// The environment variable that sets the limit.
pub(crate) const LIMIT_VARIABLE: &str = "PHI_MEMORY_LIMIT";

/// The memory limit in bytes: `PHI_MEMORY_LIMIT`, else the machine's memory (`u64::MAX` where it
/// cannot be learnt).
///
/// # Errors
/// A `PHI_MEMORY_LIMIT` that is not a size.
pub fn memory_limit() -> Result<u64> {
    match std::env::var(LIMIT_VARIABLE) {
        Ok(text) => parse_bytes(&text).with_context(|| format!("the variable {LIMIT_VARIABLE}")),
        Err(_) => Ok(machine_memory().unwrap_or(u64::MAX)),
    }
}

/// Refuses a request of about `bytes` bytes above the limit: `what` names the request (the file
/// and key or the option that sized it).
///
/// # Errors
/// The estimate exceeds [`memory_limit`], or the limit cannot be read.
pub(crate) fn check_memory(what: &str, bytes: u128) -> Result<()> {
    let limit = memory_limit()?;
    if bytes > u128::from(limit) {
        bail!(
            "{what} needs about {} of memory, more than the limit of {} (the machine's memory, \
             or {LIMIT_VARIABLE})",
            format_bytes(bytes),
            format_bytes(u128::from(limit))
        );
    }
    Ok(())
}

/// A byte count for messages: `512 B`, `3.0 GiB`, `1.2e6 TiB`.
pub(crate) fn format_bytes(bytes: u128) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else if value < 1e4 {
        format!("{value:.1} {}", UNITS[unit])
    } else {
        format!("{value:.1e} {}", UNITS[unit])
    }
}

/// `text`, or its first `max` characters and a note of its length when it is longer: for
/// echoing values of unknown size in messages.
pub fn shorten(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((cut, _)) => format!("{}… ({} bytes in all)", &text[..cut], text.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_units() {
        assert_eq!(parse_bytes("1024").unwrap(), 1024);
        assert_eq!(parse_bytes("8GiB").unwrap(), 8 << 30);
        assert_eq!(parse_bytes("1.5 k").unwrap(), 1536);
        assert_eq!(parse_bytes("2GB").unwrap(), 2_000_000_000);
        assert_eq!(parse_bytes("1e6").unwrap(), 1_000_000);
        assert!(parse_bytes("0").is_err());
        assert!(parse_bytes("lots").is_err());
        assert!(parse_bytes("3 parsecs").is_err());
        assert!(machine_memory().is_none_or(|m| m > 1 << 20));
    }

    #[test]
    fn byte_counts_read_well() {
        assert_eq!(format_bytes(512), "512 B");
        assert_eq!(format_bytes(3 << 30), "3.0 GiB");
        assert_eq!(format_bytes(1u128 << 60), "1.0e6 TiB");
    }

    #[test]
    fn long_values_are_shortened_once() {
        assert_eq!(shorten("abc", 5), "abc");
        let long = "x".repeat(1_000_000);
        let short = shorten(&long, 20);
        assert_eq!(short, format!("{}… (1000000 bytes in all)", "x".repeat(20)));
    }
}
