//! Parsing the command-line values the commands share.

use kickstart_rt_renderer::error::AnyResult;

/// Parses `--size WIDTHxHEIGHT`, each side in 1..=16384.
pub fn parse_size(size: &str) -> AnyResult<(u32, u32)> {
    let (w, h) = size
        .split_once('x')
        .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)))
        .ok_or_else(|| format!("--size {size:?}: expected WIDTHxHEIGHT, e.g. 1280x720"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("--size {w}x{h}: each side must be in 1..=16384").into());
    }
    Ok((w, h))
}

/// Parses an angle in degrees: a finite number, at most a full turn either way.
pub fn parse_degrees(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|e| format!("{s:?} is not a number of degrees: {e}"))?;
    if !v.is_finite() || v.abs() > 360.0 {
        return Err(format!("{v} degrees: must be finite and within ±360"));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degrees_are_finite_and_within_a_turn() {
        assert_eq!(parse_degrees("-8.5"), Ok(-8.5));
        for bad in ["NaN", "inf", "-inf", "361", "x"] {
            assert!(parse_degrees(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn size_parsing() {
        assert_eq!(parse_size("320x180").ok(), Some((320, 180)));
        assert!(parse_size("320").is_err());
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("axb").is_err());
    }
}
