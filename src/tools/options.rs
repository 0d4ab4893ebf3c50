//! Numeric options of the tools checked against their ranges, the range stated in the error.

/// The most pixels a side of a frame or a benchmark image (as `--size` says).
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// An option out of its range.
#[derive(Debug, thiserror::Error)]
#[error("{option} {value} is out of range: it must be {range}")]
pub struct OptionError {
    /// The option as the command line spells it, e.g. `--frames`.
    pub option: &'static str,
    /// The value given.
    pub value: String,
    /// What it must be, with its range and unit.
    pub range: String,
}

impl OptionError {
    /// `option` given `value`, which must be `range`.
    pub fn new(
        option: &'static str,
        value: impl std::fmt::Display,
        range: impl Into<String>,
    ) -> Self {
        Self {
            option,
            value: value.to_string(),
            range: range.into(),
        }
    }
}

/// Checks that `value` lies in `range` (NaN never does); `unit` follows the range in the error.
pub fn check_range<T>(
    option: &'static str,
    value: T,
    range: std::ops::RangeInclusive<T>,
    unit: &str,
) -> Result<(), OptionError>
where
    T: PartialOrd + std::fmt::Display,
{
    if range.contains(&value) {
        return Ok(());
    }
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    Err(OptionError::new(
        option,
        value,
        format!("in {}..={}{unit}", range.start(), range.end()),
    ))
}

/// Checks an image size: 1..=[`MAX_IMAGE_SIDE`] pixels a side.
pub fn check_size(option: &'static str, (w, h): (u32, u32)) -> Result<(), OptionError> {
    if (1..=MAX_IMAGE_SIDE).contains(&w) && (1..=MAX_IMAGE_SIDE).contains(&h) {
        return Ok(());
    }
    Err(OptionError::new(
        option,
        format!("{w}x{h}"),
        format!("1..={MAX_IMAGE_SIDE} pixels a side"),
    ))
}
