//! The values of options as the command line gives them: each parser
//! names what it expects, and clap puts the option's name in front.

/// A path: any text.
pub(super) fn path(s: &str) -> std::result::Result<String, String> {
    Ok(s.to_string())
}

/// `OLD=NEW`.
pub(super) fn parse_rename(s: &str) -> std::result::Result<(String, String), String> {
    match s.split_once('=') {
        Some((a, b)) if !a.is_empty() => Ok((a.to_string(), b.to_string())),
        _ => Err(format!("expects OLD=NEW, got '{s}'")),
    }
}

pub(super) fn parse_level(s: &str) -> std::result::Result<u8, String> {
    let l: u32 = s
        .parse()
        .map_err(|_| format!("expects an integer, got '{s}'"))?;
    // Out-of-range levels are reported by validation, with the maximum.
    Ok(l.min(u8::MAX as u32) as u8)
}

/// Distance bands as one option value (clap reads a bare `Vec` as several
/// values).
#[derive(Clone, Debug)]
pub struct Bands(pub(super) Vec<(f64, u8)>);

/// `D1:L1,D2:L2,...`.
pub(super) fn parse_bands(s: &str) -> std::result::Result<Bands, String> {
    let bad = || format!("expects D1:L1,D2:L2,... (distance:level pairs), got '{s}'");
    s.split(',')
        .map(|band| {
            let (d, l) = band.split_once(':').ok_or_else(bad)?;
            Ok((
                parse_finite(d).map_err(|_| bad())?,
                parse_level(l).map_err(|_| bad())?,
            ))
        })
        .collect::<std::result::Result<_, String>>()
        .map(Bands)
}

/// Distance bands with sizes, as one option value.
#[derive(Clone, Debug)]
pub struct SizeBands(pub(super) Vec<(f64, f64)>);

/// `D1:S1,D2:S2,...`.
pub(super) fn parse_size_bands(s: &str) -> std::result::Result<SizeBands, String> {
    let bad = || format!("expects D1:S1,D2:S2,... (distance:size pairs), got '{s}'");
    s.split(',')
        .map(|band| {
            let (d, c) = band.split_once(':').ok_or_else(bad)?;
            Ok((
                parse_finite(d).map_err(|_| bad())?,
                parse_finite(c).map_err(|_| bad())?,
            ))
        })
        .collect::<std::result::Result<_, String>>()
        .map(SizeBands)
}

/// `S` or `S:FINE`.
pub(super) fn parse_size_range(s: &str) -> std::result::Result<(f64, Option<f64>), String> {
    match s.split_once(':') {
        None => Ok((parse_finite(s)?, None)),
        Some((a, b)) => Ok((parse_finite(a)?, Some(parse_finite(b)?))),
    }
}

/// `NAME=MIN[:MAX]`.
pub(super) fn parse_part_levels(
    s: &str,
) -> std::result::Result<(String, (u8, Option<u8>)), String> {
    match s.split_once('=') {
        Some((name, r)) if !name.is_empty() => Ok((name.to_string(), parse_level_range(r)?)),
        _ => Err(format!("expects NAME=MIN[:MAX], got '{s}'")),
    }
}

/// `L` or `MIN:MAX`.
pub(super) fn parse_level_range(s: &str) -> std::result::Result<(u8, Option<u8>), String> {
    match s.split_once(':') {
        None => Ok((parse_level(s)?, None)),
        Some((a, b)) => Ok((parse_level(a)?, Some(parse_level(b)?))),
    }
}

pub(super) fn parse_count(s: &str) -> std::result::Result<u64, String> {
    s.parse()
        .map_err(|_| format!("expects a non-negative integer, got '{s}'"))
}

pub(super) fn parse_u32(s: &str) -> std::result::Result<u32, String> {
    s.parse()
        .map_err(|_| format!("expects a non-negative integer, got '{s}'"))
}

/// `NX,NY,NZ`: three positive counts.
pub(super) fn parse_roots(s: &str) -> std::result::Result<[u32; 3], String> {
    let bad = || format!("expects three comma-separated positive integers NX,NY,NZ, got '{s}'");
    let v: Vec<u32> = s
        .split(',')
        .map(|t| t.trim().parse::<u32>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .ok_or_else(bad)?;
    v.try_into().map_err(|_| bad())
}

pub(super) fn parse_finite(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(format!("expects a number, got '{s}'")),
    }
}

/// `N` finite comma-separated numbers.
pub(super) fn parse_numbers<const N: usize>(s: &str) -> std::result::Result<[f64; N], String> {
    let bad = || format!("expects {N} comma-separated numbers, got '{s}'");
    let v: Vec<f64> = s
        .split(',')
        .map(parse_finite)
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    v.try_into().map_err(|_| bad())
}
