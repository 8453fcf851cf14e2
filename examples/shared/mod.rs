//! Helpers of the table examples (`accuracy_table`, `kinds_table`).

/// The comma-separated values after `flag` in `args`, or `default`'s.
pub fn list(args: &[String], flag: &str, default: &str) -> Vec<String> {
    args.iter()
        .position(|a| a == flag)
        .and_then(|i| args.get(i + 1))
        .map_or(default, |s| s.as_str())
        .split(',')
        .map(str::to_owned)
        .collect()
}
