//! Memory estimates of the dataset commands: a request whose buffers would not fit is refused
//! before anything is allocated, naming what asked for them, the estimate and the limit, rather
//! than ending in an allocation failure (an abort that names nothing).
//!
//! The limit is the machine's memory, or `PHI_MEMORY_LIMIT` (bytes, with an optional `K`, `M`,
//! `G` or `T` suffix of powers of 1024, e.g. `PHI_MEMORY_LIMIT=8G`).

use anyhow::{Context, Result, bail};

/// The environment variable that sets the limit.
pub const LIMIT_VARIABLE: &str = "PHI_MEMORY_LIMIT";

/// Parses a size: a whole number of bytes with an optional `K`, `M`, `G` or `T` suffix (powers of
/// 1024, case-insensitive, an optional trailing `B` or `iB`).
///
/// # Errors
/// Anything else, or a size past `u64`.
pub fn parse_size(text: &str) -> Result<u64> {
    let t = text.trim();
    let upper = t.to_ascii_uppercase();
    let stripped = upper
        .strip_suffix("IB")
        .or_else(|| upper.strip_suffix('B'))
        .unwrap_or(&upper);
    let (digits, shift) = match stripped.chars().last() {
        Some('K') => (&stripped[..stripped.len() - 1], 10),
        Some('M') => (&stripped[..stripped.len() - 1], 20),
        Some('G') => (&stripped[..stripped.len() - 1], 30),
        Some('T') => (&stripped[..stripped.len() - 1], 40),
        _ => (stripped, 0),
    };
    let value: u64 = digits
        .trim()
        .parse()
        .with_context(|| format!("{:?} is not a size such as 8G or 500000000", shorten(t, 40)))?;
    value
        .checked_mul(1u64 << shift)
        .with_context(|| format!("{t:?} is too large"))
}

/// The memory limit in bytes: `PHI_MEMORY_LIMIT`, else the machine's memory (`u64::MAX` where it
/// cannot be learnt).
///
/// # Errors
/// A `PHI_MEMORY_LIMIT` that is not a size.
pub fn memory_limit() -> Result<u64> {
    match std::env::var(LIMIT_VARIABLE) {
        Ok(text) => parse_size(&text).with_context(|| format!("the variable {LIMIT_VARIABLE}")),
        Err(_) => {
            let system = sysinfo::System::new_with_specifics(
                sysinfo::RefreshKind::nothing()
                    .with_memory(sysinfo::MemoryRefreshKind::nothing().with_ram()),
            );
            Ok(match system.total_memory() {
                0 => u64::MAX,
                n => n,
            })
        }
    }
}

/// Refuses a request of about `bytes` bytes above the limit: `what` names the request (the file
/// and key or the option that sized it).
///
/// # Errors
/// The estimate exceeds [`memory_limit`], or the limit cannot be read.
pub fn check_memory(what: &str, bytes: u128) -> Result<()> {
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
pub fn format_bytes(bytes: u128) -> String {
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
    fn sizes_parse_with_binary_suffixes() {
        assert_eq!(parse_size("512").unwrap(), 512);
        assert_eq!(parse_size("8G").unwrap(), 8 << 30);
        assert_eq!(parse_size(" 3 mib ").unwrap(), 3 << 20);
        assert_eq!(parse_size("2KB").unwrap(), 2048);
        assert!(parse_size("lots").is_err());
        assert!(parse_size("-1G").is_err());
        assert!(parse_size("99999999999T").is_err());
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
