//! Every option of `octmesh octree` and `octmesh mesh`, declared once.
//!
//! Each entry of [`OPTIONS`] gives an option's command-line name, value,
//! help, the case-file keys it fills, its default and its range, and how
//! its value is read and stored in a [`Config`]. From the table come:
//!
//! - the command's arguments ([`super::cli`] builds its clap command from
//!   [`clap_args`] and applies the values given with [`Opt::apply`]),
//! - the case file's keys ([`keys`]: the names a validation error can give),
//! - the range checks of [`Config::validate`], of the snap
//!   ([`check_snap`]) and of the C API's settings ([`check_key`]),
//! - the reference `docs/options.md` ([`markdown`]).
//!
//! The case file's keys themselves are the fields of [`Config`] (serde);
//! each entry names the fields it fills. Defaults of fields that always
//! hold a value are those of `Config::default()` (read back from it for
//! the help and the reference); an unset key's fallback is a constant the
//! entry shows and the configuration's accessor uses.
//!
//! Adding an option: a field in `config/mod.rs` (with its default), and an
//! entry here.

use clap::parser::ValueSource;
use clap::{Arg, ArgAction, ArgMatches};

use super::{Balance, Config, ConfigError, DomainConfig};
use crate::classify::{CutRule, InsideRule, Keep};
use crate::error::{Error, Result};
use crate::io::openfoam::FoamFormat;
use crate::octree::octant::MAX_LEVEL;
use crate::refine::regions::Region;
use crate::run::budget::ByteSize;

pub use super::reference::markdown;
use super::values::*;

/// The feature angle of curvature refinement when `octree.feature_angle`
/// is unset, degrees (snappyHexMesh's `resolveFeatureAngle` default).
pub const DEFAULT_FEATURE_ANGLE: f64 = 30.0;

/// The elements `output.quality_out` holds when `output.quality_worst` is
/// unset.
pub const DEFAULT_QUALITY_WORST: u64 = 100;

/// Which commands take an option.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    /// `octree` and `mesh`.
    Octree,
    /// `mesh` only.
    Mesh,
}

/// How an option takes its value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// The positional argument (the surface or a case file).
    Input,
    /// A switch without a value.
    Switch,
    /// One value.
    One,
    /// A value, repeatable.
    Many,
}

/// The values a numeric key accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Range {
    /// A level: 0 to [`MAX_LEVEL`].
    Level,
    /// A count from 0 up to this.
    AtMost(u64),
    /// A count from this up.
    AtLeast(u64),
    /// Real numbers from `lo` to `hi`, each end included or not, in `unit`
    /// (empty: none).
    Real {
        /// Lower end.
        lo: f64,
        /// Whether `lo` is allowed.
        lo_in: bool,
        /// Upper end.
        hi: f64,
        /// Whether `hi` is allowed.
        hi_in: bool,
        /// The unit's name, e.g. `degrees`.
        unit: &'static str,
    },
}

impl Range {
    /// Whether `v` is in the range (NaN never is).
    pub fn contains(&self, v: f64) -> bool {
        match *self {
            Range::Level => (0.0..=MAX_LEVEL as f64).contains(&v),
            Range::AtMost(n) => (0.0..=n as f64).contains(&v),
            Range::AtLeast(n) => v >= n as f64,
            Range::Real {
                lo,
                lo_in,
                hi,
                hi_in,
                ..
            } => (if lo_in { v >= lo } else { v > lo }) && (if hi_in { v <= hi } else { v < hi }),
        }
    }

    /// What follows a key's name when `v` is out of the range.
    pub fn complaint(&self, v: f64) -> String {
        match self {
            Range::Level => format!("is {v}: above the maximum level {MAX_LEVEL}"),
            Range::AtMost(n) => format!("must be at most {n}, got {v}"),
            Range::AtLeast(n) => format!("must be at least {n}, got {v}"),
            Range::Real { .. } => format!("must be in {self}, got {v}"),
        }
    }

    /// `Err(complaint)` when `v` is out of the range.
    pub fn check(&self, v: f64) -> std::result::Result<(), String> {
        match self.contains(v) {
            true => Ok(()),
            false => Err(self.complaint(v)),
        }
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Range::Level => write!(f, "0 to {MAX_LEVEL}"),
            Range::AtMost(n) => write!(f, "0 to {n}"),
            Range::AtLeast(n) => write!(f, "{n} or more"),
            Range::Real {
                lo,
                lo_in,
                hi,
                hi_in,
                unit,
            } => {
                let (open, close) = (if lo_in { '[' } else { '(' }, if hi_in { ']' } else { ')' });
                write!(f, "{open}{lo}, {hi}{close}")?;
                match unit {
                    "" => Ok(()),
                    u => write!(f, " {u}"),
                }
            }
        }
    }
}

/// `(lo, hi]`.
const fn above_upto(lo: f64, hi: f64, unit: &'static str) -> Range {
    Range::Real {
        lo,
        lo_in: false,
        hi,
        hi_in: true,
        unit,
    }
}

/// `(0, inf)`.
const POSITIVE: Range = Range::Real {
    lo: 0.0,
    lo_in: false,
    hi: f64::INFINITY,
    hi_in: false,
    unit: "",
};

/// How an entry gives its default.
#[derive(Clone, Copy, Debug)]
pub enum DefaultValue {
    /// None: the key is unset unless given.
    None,
    /// The value `Config::default()` holds for the entry's first key.
    Config,
    /// The key stays unset, and the configuration falls back to this.
    Shown(fn() -> String),
}

/// Keys set by the command line, for error messages.
pub type Given = Vec<&'static str>;

/// The value of a numeric key as a number, if it is set.
pub type KeyValue = fn(&Config) -> Option<f64>;

/// One option.
pub struct Opt {
    /// The long name, `level` for `--level` (for the input: `input`).
    pub name: &'static str,
    /// The value's name in the help, `None` for a switch.
    pub value: Option<&'static str>,
    /// How it takes its value.
    pub kind: Kind,
    /// The commands that take it.
    pub scope: Scope,
    /// The case-file keys it fills (none for a command-line-only switch).
    pub keys: &'static [&'static str],
    /// What it does.
    pub help: &'static str,
    /// Its default.
    pub default: DefaultValue,
    /// What its first key accepts, checked by [`Config::validate`] for
    /// any front end, and how to read that key's value.
    pub range: Option<(Range, KeyValue)>,
    /// A note on the default that no value expresses.
    pub default_note: Option<&'static str>,
    /// Whether values may start with `-`.
    pub hyphen: bool,
    arg: fn(Arg) -> Arg,
    apply: fn(&ArgMatches, &mut Config, &mut Given) -> Result<()>,
}

impl Opt {
    /// The option as written on the command line: `--level`, or `INPUT`.
    pub fn flag(&self) -> String {
        match self.kind {
            Kind::Input => "INPUT".to_string(),
            _ => format!("--{}", self.name),
        }
    }

    /// The default as text, if there is one.
    pub fn default_text(&self) -> Option<String> {
        match self.default {
            DefaultValue::None => None,
            DefaultValue::Shown(f) => Some(f()),
            DefaultValue::Config => {
                let key = self.keys.first()?;
                let full: toml::Table = toml::from_str(&Config::default().to_toml()).ok()?;
                let (table, field) = key.split_once('.')?;
                let v = full.get(table)?.as_table()?.get(field)?;
                Some(match v {
                    toml::Value::String(s) => s.clone(),
                    toml::Value::Float(x) => x.to_string(),
                    other => other.to_string(),
                })
            }
        }
        .or(self.default_note.map(str::to_string))
    }

    /// The help as `--help` shows it: the text, the range, the default.
    pub fn full_help(&self) -> String {
        let mut h = self.help.trim().to_string();
        if let Some((r, _)) = &self.range {
            h.push_str(&format!(" [range: {r}]"));
        }
        if let Some(d) = self.default_text() {
            h.push_str(&format!(" [default: {d}]"));
        }
        h
    }

    /// The clap argument.
    pub fn clap_arg(&self) -> Arg {
        let a = Arg::new(self.name).help(self.full_help());
        let a = match self.kind {
            Kind::Input => a.required(true),
            _ => a.long(self.name),
        };
        let a = match self.value {
            Some(v) => a.value_name(v),
            None => a,
        };
        (self.arg)(a.allow_hyphen_values(self.hyphen))
    }

    /// Stores the value given on the command line, if any, in `config` and
    /// notes the keys it set in `given`.
    pub fn apply(&self, m: &ArgMatches, config: &mut Config, given: &mut Given) -> Result<()> {
        (self.apply)(m, config, given)
    }
}

/// Whether `name` was given on the command line.
fn on_line(m: &ArgMatches, name: &str) -> bool {
    m.value_source(name) == Some(ValueSource::CommandLine)
}

/// Declares the table: per entry, doc comments (the help), the scope, the
/// name, the value's name, the kind and type (with its parser), the keys,
/// the default, the range (with the key's value as a number), and the
/// setter, a block on the configuration `c`, the value `v` and the keys
/// given `g` (the first key is noted before it runs). A setter may `return
/// Err(...)`.
macro_rules! options {
    ($(
        $(#[doc = $help:literal])+
        $scope:ident $name:literal $(<$value:literal>)? $(hyphen $hy:ident)?
            : $kind:ident $t:ty $(= $parser:expr)?,
        keys [$($key:literal),*],
        default $dk:ident $(($d:expr))? $(note $note:literal)?,
        range $($range:expr => |$rc:ident| $rv:expr)?,
        set |$c:ident, $v:ident, $g:pat_param| $set:block
    )*) => {
        /// Every option of `octree` and `mesh`, in the order of `--help`.
        pub static OPTIONS: &[Opt] = &[$(
            Opt {
                name: $name,
                value: options!(@value $($value)?),
                kind: Kind::$kind,
                scope: Scope::$scope,
                keys: &[$($key),*],
                help: concat!($($help),+),
                default: options!(@default $dk $($d)?),
                range: options!(@range $($range => |$rc| $rv)?),
                default_note: options!(@value $($note)?),
                hyphen: options!(@hyphen $($hy)?),
                arg: |a| options!(@arg a $kind $t $(, $parser)?),
                apply: |m, c, g| {
                    let keys: &[&'static str] = &[$($key),*];
                    match options!(@get m $name $kind $t) {
                        Some(value) => {
                            g.extend(keys.first());
                            let ($c, $v, $g) = (c, value, g);
                            $set
                            Ok(())
                        }
                        None => Ok(()),
                    }
                },
            },
        )*];
    };
    (@value) => { None };
    (@value $v:literal) => { Some($v) };
    (@hyphen) => { false };
    (@hyphen $h:ident) => { true };
    (@default none) => { DefaultValue::None };
    (@default config) => { DefaultValue::Config };
    (@default shown $d:expr) => { DefaultValue::Shown(|| $d.to_string()) };
    (@range) => { None };
    (@range $r:expr => |$rc:ident| $rv:expr) => {
        Some(($r, (|$rc: &Config| $rv) as KeyValue))
    };
    (@arg $a:ident Input $t:ty) => { $a };
    (@arg $a:ident Switch $t:ty) => { $a.action(ArgAction::SetTrue) };
    (@arg $a:ident One $t:ty, $p:expr) => { $a.action(ArgAction::Set).value_parser($p) };
    (@arg $a:ident Many $t:ty, $p:expr) => { $a.action(ArgAction::Append).value_parser($p) };
    (@get $m:ident $n:literal Input $t:ty) => {{ let _ = $m; None::<$t> }};
    (@get $m:ident $n:literal Switch $t:ty) => { $m.get_flag($n).then_some(true) };
    (@get $m:ident $n:literal One $t:ty) => {
        on_line($m, $n).then(|| $m.get_one::<$t>($n).cloned()).flatten()
    };
    (@get $m:ident $n:literal Many $t:ty) => {
        on_line($m, $n)
            .then(|| $m.get_many::<$t>($n).map(|v| v.cloned().collect::<Vec<$t>>()))
            .flatten()
    };
}

options! {
    /// An STL file (ASCII or binary), the built-in `sphere`, `torus` or `hull`, or
    /// a case file (`.toml`) whose settings the options below override
    Octree "input" <"INPUT">: Input String,
    keys ["surface.file"],
    default none,
    range,
    set |_c, _v, _g| {}

    /// Another surface meshed with the first (an STL file or a built-in
    /// name), repeatable: each file is a part with its own patch and, with
    /// --surface-level, its own levels
    Octree "surface" <"FILE">: Many String = path,
    keys ["surface.others"],
    default none,
    range,
    set |c, v, _g| {
        // The command line's extra surfaces replace the case file's.
        c.surface.others = v;
    }

    /// Level of the leaves touching the surface; MIN:MAX refines
    /// them further, up to MAX, where the surface curves by more than the
    /// feature angle
    Octree "level" <"L[:MAX]">: One (u8, Option<u8>) = parse_level_range,
    keys ["octree.level", "octree.max_level"],
    default none,
    range Range::Level => |c| c.octree.level.map(f64::from),
    set |c, v, g| {
        c.octree.level = Some(v.0);
        if v.1.is_some() {
            g.push("octree.max_level");
            c.octree.max_level = v.1;
        }
    }

    /// Levels of one part of the surface (a solid of an ASCII STL, by its
    /// patch name), NAME=MIN[:MAX], repeatable; --level applies to the rest
    Octree "surface-level" <"NAME=MIN[:MAX]">: Many (String, (u8, Option<u8>)) = parse_part_levels,
    keys ["octree.surface_levels"],
    default none,
    range,
    set |c, v, _g| {
        // The command line's part levels replace the case file's.
        c.octree.surface_levels.clear();
        for (name, (min, max)) in v {
            let r = [min, max.unwrap_or(min)];
            if c.octree.surface_levels.insert(name.clone(), r).is_some() {
                return Err(Error::invalid(format!(
                    "--surface-level gives '{name}' twice"
                )));
            }
        }
    }

    /// Feature angle of curvature refinement, degrees
    Octree "feature-angle" <"DEG">: One f64 = parse_finite,
    keys ["octree.feature_angle"],
    default shown (DEFAULT_FEATURE_ANGLE),
    range Range::Real { lo: 0.0, lo_in: false, hi: 180.0, hi_in: false, unit: "degrees" }
        => |c| c.octree.feature_angle,
    set |c, v, _g| { c.octree.feature_angle = Some(v); }

    /// Every leaf at least this level
    Octree "min-level" <"L">: One u8 = parse_level,
    keys ["octree.min_level"],
    default config,
    range Range::Level => |c| Some(c.octree.min_level.into()),
    set |c, v, _g| { c.octree.min_level = v; }

    /// The surface level as a cell size in user units instead of --level:
    /// the coarsest level whose cell is not larger; S:FINE gives the
    /// curvature refinement's finest size
    Octree "size" <"S[:FINE]">: One (f64, Option<f64>) = parse_size_range,
    keys ["octree.size", "octree.max_size"],
    default none,
    range,
    set |c, v, g| {
        c.octree.size = Some(v.0);
        if v.1.is_some() {
            g.push("octree.max_size");
            c.octree.max_size = v.1;
        }
    }

    /// --min-level as a cell size: every leaf at most this large
    Octree "min-size" <"S">: One f64 = parse_finite,
    keys ["octree.min_size"],
    default none,
    range,
    set |c, v, _g| { c.octree.min_size = Some(v); }

    /// Distance bands around the surface, D1:L1,D2:L2,... with increasing
    /// distances D (user units): leaves within D of the surface get level L
    Octree "distance" <"D:L,...">: One Bands = parse_bands,
    keys ["octree.distance"],
    default none,
    range,
    set |c, v, _g| { c.octree.distance = v.0; }

    /// Distance bands with cell sizes instead of levels, D1:S1,D2:S2,...
    /// (user units): leaves within D of the surface get the coarsest level
    /// whose cell is not larger than S
    Octree "distance-size" <"D:S,...">: One SizeBands = parse_size_bands,
    keys ["octree.distance_size"],
    default none,
    range,
    set |c, v, _g| { c.octree.distance_size = v.0; }

    /// A refinement region, repeatable: box:X0,Y0,Z0,X1,Y1,Z1:LEVEL,
    /// sphere:CX,CY,CZ,R:LEVEL or cylinder:X0,Y0,Z0,X1,Y1,Z1,R:LEVEL (user
    /// units), then :outside to refine where the shape is not, then
    /// :zone=NAME to put the elements centred where it refines in zone NAME
    /// (with --zones; `zone = "NAME"` in a [[regions]] table)
    Octree "region" <"SHAPE:NUMBERS:LEVEL"> hyphen yes: Many Region = Region::parse,
    keys ["regions"],
    default none,
    range,
    set |c, v, _g| {
        // The command line's regions replace the case file's.
        c.regions = v;
    }

    /// 2:1 balance: face, edge, corner or none
    Octree "balance" <"KIND">: One Balance = Balance::parse,
    keys ["octree.balance"],
    default config,
    range,
    set |c, v, _g| { c.octree.balance = v; }

    /// Longest side of the surface's bounding box as a fraction of the cube
    /// side
    Octree "fit" <"F"> hyphen yes: One f64 = parse_finite,
    keys ["domain.fit"],
    default shown (crate::octree::domain::DEFAULT_FIT),
    range above_upto(0.0, 1.0, "") => |c| c.domain.fit,
    set |c, v, _g| {
        // The command line's domain replaces the case file's.
        c.domain = DomainConfig { fit: Some(v), ..DomainConfig::default() };
    }

    /// Explicit cube instead of --fit: lowest corner X,Y,Z and side S, user
    /// units
    Octree "domain" <"X,Y,Z,S"> hyphen yes: One [f64; 4] = parse_numbers::<4>,
    keys ["domain.cube"],
    default none,
    range,
    set |c, v, _g| { c.domain = DomainConfig { cube: Some(v), ..DomainConfig::default() }; }

    /// A box domain instead of the cube: lowest corner X0,Y0,Z0 and highest
    /// X1,Y1,Z1, user units, split into the --roots cubic root cells
    Octree "box" <"X0,Y0,Z0,X1,Y1,Z1"> hyphen yes: One [f64; 6] = parse_numbers::<6>,
    keys ["domain.box"],
    default none,
    range,
    set |c, v, _g| {
        c.domain = DomainConfig { bbox: Some(v), roots: c.domain.roots, ..DomainConfig::default() };
    }

    /// Root cells of --box along x, y, z (trees of the forest; levels count
    /// from them)
    Octree "roots" <"NX,NY,NZ">: One [u32; 3] = parse_roots,
    keys ["domain.roots"],
    default shown ("1,1,1"),
    range,
    set |c, v, _g| { c.domain.roots = Some(v); }

    /// Stop with an error instead of building more than N leaves (refinement
    /// and balance); refused before refining when the estimate is above 2N
    Octree "max-octants" <"N">: One u64 = parse_count,
    keys ["octree.max_octants"],
    default none,
    range,
    set |c, v, _g| { c.octree.max_octants = Some(v); }

    /// Memory each rank may use (512MiB, 4GiB, ...): a run expected to need
    /// more stops before refining with the largest level that fits
    Octree "memory-budget" <"SIZE">: One ByteSize = ByteSize::parse,
    keys ["octree.memory_budget"],
    default none note "the node's available memory shared among its ranks",
    range,
    set |c, v, _g| { c.octree.memory_budget = Some(v); }

    /// Write counts, timings (seconds, max over ranks), peak memory (bytes,
    /// max over ranks) and bytes exchanged per phase as JSON
    Octree "stats" <"FILE.json">: One String = path,
    keys ["output.stats"],
    default none,
    range,
    set |c, v, _g| { c.output.stats = Some(v.into()); }

    /// Write the balanced leaves, one `x y z level` per line in lattice units
    /// (.bin: binary)
    Octree "write-leaves" <"FILE">: One String = path,
    keys ["output.leaves"],
    default none,
    range,
    set |c, v, _g| { c.output.leaves = Some(v.into()); }

    /// Write the leaves before balance, same format
    Octree "write-refined" <"FILE">: One String = path,
    keys ["output.refined_leaves"],
    default none,
    range,
    set |c, v, _g| { c.output.refined_leaves = Some(v.into()); }

    /// Save the balanced octree to one checkpoint file (each rank writes
    /// its leaves at their offset; reloads on any number of ranks with
    /// `mesh --load`, see docs/formats.md)
    Octree "save" <"FILE.ckpt">: One String = path,
    keys ["output.save"],
    default none,
    range,
    set |c, v, _g| { c.output.save = Some(v.into()); }

    /// Take the octree of a checkpoint written by --save instead of
    /// refining (the surface must be the one it was saved from)
    Octree "load" <"FILE.ckpt">: One String = path,
    keys ["octree.load"],
    default none,
    range,
    set |c, v, _g| { c.octree.load = Some(v.into()); }

    /// Remove zero-area facets right after loading
    Octree "drop-degenerate": Switch bool,
    keys ["surface.drop_degenerate"],
    default none,
    range,
    set |c, _v, _g| { c.surface.drop_degenerate = true; }

    /// On several ranks, each rank reads a share of the surface and keeps
    /// only the triangles near its part of the domain (binary STL files are
    /// read in shares). Used with the parity rule and without snapping,
    /// zones, several parts, clean-up or checkpoints; otherwise every rank
    /// holds the whole surface, as without it. The same mesh either way
    Octree "distributed-surface": Switch bool,
    keys ["surface.distributed"],
    default none,
    range,
    set |c, _v, _g| { c.surface.distributed = true; }

    /// Remove facets with the same (welded) vertices as an earlier facet
    Octree "drop-duplicates": Switch bool,
    keys ["surface.drop_duplicates"],
    default none,
    range,
    set |c, _v, _g| { c.surface.drop_duplicates = true; }

    /// How a leaf's centre is found inside: parity (ray parity), winding
    /// (generalized winding number above 1/2: holes, overlapping parts,
    /// flipped facets) or auto (parity for one closed, consistently oriented
    /// component, else winding; the default for mesh). With octree, also
    /// classifies the leaves and counts them
    Octree "inside" <"RULE">: One InsideRule = InsideRule::parse,
    keys ["classify.inside"],
    default none,
    range,
    set |c, v, _g| { c.classify.inside = Some(v); }

    /// A point inside the body (user units): after balance, fail with a leak
    /// report if the region outside the surface reaches it
    Octree "inside-point" <"X,Y,Z"> hyphen yes: One [f64; 3] = parse_numbers::<3>,
    keys ["leak.inside_point"],
    default none,
    range,
    set |c, v, _g| { c.leak.inside_point = Some(v); }

    /// With --inside-point, write a leak's path (.vtk: legacy VTK lines; any
    /// other name: CSV step,x,y,z,size,level)
    Octree "leak-path" <"FILE">: One String = path,
    keys ["leak.path"],
    default none,
    range,
    set |c, v, _g| { c.leak.path = Some(v.into()); }

    /// Print nothing but errors
    Octree "quiet": Switch bool,
    keys ["output.quiet"],
    default none,
    range,
    set |c, _v, _g| { c.output.quiet = true; }

    /// Print the case file (TOML) equivalent to this command line and stop
    Octree "print-case": Switch bool,
    keys [],
    default none,
    range,
    set |_c, _v, _g| {}

    /// Print the estimated octant count of each refinement control and
    /// stop, without building anything
    Octree "dry-run": Switch bool,
    keys [],
    default none,
    range,
    set |_c, _v, _g| {}

    /// Which leaves become elements: all, inside (solid) or outside (fluid)
    Mesh "keep" <"WHICH">: One Keep = Keep::parse,
    keys ["mesh.keep"],
    default config,
    range,
    set |c, v, _g| { c.mesh.keep = v; }

    /// For inside or outside: leaves touching the surface are kept when their
    /// centre is on the kept side (center), always (all) or never (none)
    Mesh "cut-rule" <"RULE">: One CutRule = CutRule::parse,
    keys ["mesh.cut_rule"],
    default config,
    range,
    set |c, v, _g| { c.mesh.cut_rule = v; }

    /// Write one binary VTU per rank and a PVTU (cell data level, rank,
    /// class; point data global_id, hanging)
    Mesh "out" <"NAME.pvtu">: One String = path,
    keys ["output.vtu"],
    default none,
    range,
    set |c, v, _g| { c.output.vtu = Some(v.into()); }

    /// Write an OpenFOAM case: DIR/constant/polyMesh on one rank,
    /// DIR/processor<r>/constant/polyMesh on several (run solvers with
    /// -parallel), and the system/ files that are absent
    Mesh "openfoam" <"DIR">: One String = path,
    keys ["output.openfoam"],
    default none,
    range,
    set |c, v, _g| { c.output.openfoam = Some(v.into()); }

    /// Write one Gmsh MSH 4.1 file (ASCII; gathered on rank 0): physical
    /// surfaces per patch, the hanging nodes as plain nodes with their
    /// constraints in a `$HangingNodes` section (see docs/formats.md)
    Mesh "gmsh" <"FILE.msh">: One String = path,
    keys ["output.gmsh"],
    default none,
    range,
    set |c, v, _g| { c.output.gmsh = Some(v.into()); }

    /// Write one Abaqus/CalculiX input file (gathered on rank 0): `*NODE`,
    /// C3D8 `*ELEMENT`, `*NSET`/`*ELSET`/`*SURFACE` per patch, an
    /// `*EQUATION` per hanging node and degree of freedom
    Mesh "abaqus" <"FILE.inp">: One String = path,
    keys ["output.abaqus"],
    default none,
    range,
    set |c, v, _g| { c.output.abaqus = Some(v.into()); }

    /// Write one Exodus II file (netCDF; gathered on rank 0): element
    /// block `volume`, a side set and a node set per patch, the hanging
    /// nodes as a node set `hanging` with their parents and weights in
    /// extra variables (see docs/formats.md)
    Mesh "exodus" <"FILE.exo">: One String = path,
    keys ["output.exodus"],
    default none,
    range,
    set |c, v, _g| { c.output.exodus = Some(v.into()); }

    /// Write one CGNS file (HDF5; gathered on rank 0): an unstructured
    /// zone of HEXA_8, a QUAD_4 section, boundary condition and family per
    /// patch, the hanging nodes' constraints as user data (see
    /// docs/formats.md)
    Mesh "cgns" <"FILE.cgns">: One String = path,
    keys ["output.cgns"],
    default none,
    range,
    set |c, v, _g| { c.output.cgns = Some(v.into()); }

    /// Lists in the OpenFOAM files: binary or ascii
    Mesh "openfoam-format" <"FORMAT">: One FoamFormat = FoamFormat::parse,
    keys ["output.openfoam_format"],
    default config,
    range,
    set |c, v, _g| { c.output.openfoam_format = v; }

    /// Replace an existing OpenFOAM mesh
    Mesh "overwrite": Switch bool,
    keys ["output.overwrite"],
    default none,
    range,
    set |c, _v, _g| { c.output.overwrite = true; }

    /// Rename a patch, OLD=NEW (repeatable): the sides xmin xmax ymin ymax
    /// zmin zmax, the surface by its file's stem or as `surface`
    Mesh "patch" <"OLD=NEW">: Many (String, String) = parse_rename,
    keys ["mesh.patches"],
    default none,
    range,
    set |c, v, _g| {
        for (a, b) in v {
            if c.mesh.patches.insert(a.clone(), b).is_some() {
                return Err(Error::invalid(format!("--patch renames '{a}' twice")));
            }
        }
    }

    /// Drop kept leaves touching the rest only along an edge or at a
    /// corner, or with kept neighbours along fewer than three axes, so the
    /// walls are manifold
    Mesh "clean-walls" <"BOOL">: One bool = clap::value_parser!(bool),
    keys ["mesh.clean_walls"],
    default none note "true with --openfoam, --gmsh, --abaqus, --exodus or --cgns, else false",
    range,
    set |c, v, _g| { c.mesh.clean_walls = Some(v); }

    /// Mark every element with a zone: inside or outside of the surface, or
    /// the zone of the last region (--region ...:zone=NAME) holding its
    /// centre; OpenFOAM cellZones with a faceZone per interface, Gmsh
    /// physical volumes (needs --keep all)
    Mesh "zones": Switch bool,
    keys ["mesh.zones"],
    default none,
    range,
    set |c, _v, _g| { c.mesh.zones = true; }

    /// Write --gmsh, --abaqus, --exodus, --cgns, --openfoam (one serial
    /// case) and --out (the whole mesh in rank 0's piece) as conforming
    /// all-hexahedral meshes (no hanging nodes) from refinement templates,
    /// refining where no template fits (around a surface's staircase: up
    /// to the finest level); --snap snaps it and --quality measures it;
    /// without the wall layer
    Mesh "conforming": Switch bool,
    keys ["mesh.conforming"],
    default none,
    range,
    set |c, _v, _g| { c.mesh.conforming = true; }

    /// Add a layer of cells between the staircase and the surface in the
    /// OpenFOAM case: every wall point on the surface, no old cell with a
    /// face on the wall (needs --keep inside or outside, --cut-rule none
    /// and --openfoam as the only mesh output; instead of --snap)
    Mesh "wall-layer": Switch bool,
    keys ["mesh.wall_layer"],
    default none,
    range,
    set |c, _v, _g| { c.mesh.wall_layer = true; }

    /// Boundary layers in the OpenFOAM case: N cells on every wall face
    /// next to the surface, growing by --layer-expansion away from it, the
    /// thickness from --first-layer, --final-layer or --layer-thickness
    /// (implies --wall-layer and its needs; [[layers]] tables in a case
    /// file set them per patch)
    Mesh "layers" <"N">: One u32 = parse_u32,
    keys ["mesh.layers", "layers"],
    default none,
    range Range::AtLeast(1) => |c| c.mesh.layers.map(f64::from),
    set |c, v, _g| { c.mesh.layers = Some(v); }

    /// Each boundary layer's height over the one before it, from the wall
    /// out (snappyHexMesh's expansionRatio)
    Mesh "layer-expansion" <"R"> hyphen yes: One f64 = parse_finite,
    keys ["mesh.layer_expansion"],
    default config,
    range POSITIVE => |c| Some(c.mesh.layer_expansion),
    set |c, v, _g| { c.mesh.layer_expansion = v; }

    /// The first boundary layer's height, on the wall (surface units, or
    /// with --relative-sizes a fraction of the wall cell)
    Mesh "first-layer" <"T"> hyphen yes: One f64 = parse_finite,
    keys ["mesh.first_layer"],
    default none,
    range POSITIVE => |c| c.mesh.first_layer,
    set |c, v, _g| { c.mesh.first_layer = Some(v); }

    /// The last boundary layer's height, the farthest from the wall
    Mesh "final-layer" <"T"> hyphen yes: One f64 = parse_finite,
    keys ["mesh.final_layer"],
    default none,
    range POSITIVE => |c| c.mesh.final_layer,
    set |c, v, _g| { c.mesh.final_layer = Some(v); }

    /// The boundary layers' total thickness
    Mesh "layer-thickness" <"T"> hyphen yes: One f64 = parse_finite,
    keys ["mesh.layer_thickness"],
    default none,
    range POSITIVE => |c| c.mesh.layer_thickness,
    set |c, v, _g| { c.mesh.layer_thickness = Some(v); }

    /// Layer thicknesses are fractions (below 1) of the local wall cell's
    /// side, as snappyHexMesh's relativeSizes
    Mesh "relative-sizes": Switch bool,
    keys ["mesh.relative_sizes"],
    default none,
    range,
    set |c, _v, _g| { c.mesh.relative_sizes = true; }

    /// Snap the mesh to the surface: the nodes on the surface move onto
    /// it (sharp edges kept), scaled back where an element would be
    /// invalid, the layers next to it relaxed (needs --keep inside or
    /// outside; with --conforming the conforming mesh is snapped)
    Mesh "snap": Switch bool,
    keys ["mesh.snap"],
    default none,
    range,
    set |c, _v, _g| { c.mesh.snap = true; }

    /// Surface edges whose facets' normals differ by more than this many
    /// degrees stay sharp in the snapped mesh
    Mesh "snap-feature-angle" <"DEGREES">: One f64 = parse_finite,
    keys ["mesh.snap_feature_angle"],
    default config,
    range Range::Real { lo: 0.0, lo_in: true, hi: 180.0, hi_in: true, unit: "degrees" }
        => |c| Some(c.mesh.snap_feature_angle),
    set |c, v, _g| { c.mesh.snap_feature_angle = v; }

    /// Element layers around the surface nodes the snap relaxes
    Mesh "snap-layers" <"N">: One u32 = parse_u32,
    keys ["mesh.snap_layers"],
    default config,
    range Range::AtMost(100) => |c| Some(c.mesh.snap_layers.into()),
    set |c, v, _g| { c.mesh.snap_layers = v; }

    /// Relaxation iterations of the snap
    Mesh "snap-iterations" <"N">: One u32 = parse_u32,
    keys ["mesh.snap_iterations"],
    default config,
    range Range::AtMost(1000) => |c| Some(c.mesh.snap_iterations.into()),
    set |c, v, _g| { c.mesh.snap_iterations = v; }

    /// The least scaled Jacobian an element's corner may have after the
    /// snap
    Mesh "snap-min-jacobian" <"J">: One f64 = parse_finite,
    keys ["mesh.snap_min_jacobian"],
    default shown (format!(
        "{} with --openfoam, else {}",
        crate::mesh::snap::FOAM_MIN_JACOBIAN,
        crate::mesh::snap::DEFAULT_MIN_JACOBIAN
    )),
    range above_upto(0.0, 0.5, "") => |c| c.mesh.snap_min_jacobian,
    set |c, v, _g| { c.mesh.snap_min_jacobian = Some(v); }

    /// Measure the mesh's quality: scaled Jacobian histogram, checkMesh's
    /// non-orthogonality and skewness, in the table and --stats
    Mesh "quality": Switch bool,
    keys ["output.quality"],
    default none,
    range,
    set |c, _v, _g| { c.output.quality = true; }

    /// Measure the quality and write the worst elements by scaled Jacobian
    /// to a VTU file
    Mesh "quality-out" <"FILE.vtu">: One String = path,
    keys ["output.quality_out"],
    default none,
    range,
    set |c, v, _g| { c.output.quality_out = Some(v.into()); }

    /// How many elements --quality-out writes
    Mesh "quality-worst" <"N">: One u64 = parse_count,
    keys ["output.quality_worst"],
    default shown (DEFAULT_QUALITY_WORST),
    range Range::AtLeast(1) => |c| c.output.quality_worst.map(|n| n as f64),
    set |c, v, _g| { c.output.quality_worst = Some(v); }
}

/// Every case-file key, `table.field` (and `regions`), in the table's
/// order.
pub fn keys() -> impl Iterator<Item = &'static str> {
    OPTIONS.iter().flat_map(|o| o.keys.iter().copied())
}

/// The option that fills `key`, as written on the command line.
pub fn option_of(key: &str) -> String {
    match OPTIONS.iter().find(|o| o.keys.contains(&key)) {
        Some(o) if o.kind == Kind::Input => "the surface argument".to_string(),
        Some(o) => o.flag(),
        None => "an option".to_string(),
    }
}

/// The entry that fills `key`.
pub fn entry(key: &str) -> Option<&'static Opt> {
    OPTIONS.iter().find(|o| o.keys.first() == Some(&key))
}

/// The clap arguments of a command: `mesh` takes every option, `octree`
/// those of its scope.
pub fn clap_args(mesh: bool) -> impl Iterator<Item = Arg> {
    OPTIONS
        .iter()
        .filter(move |o| mesh || o.scope == Scope::Octree)
        .map(Opt::clap_arg)
}

/// Checks every key with a declared range (the `mesh` scope's only when
/// `mesh`), in the table's order.
pub fn check_ranges(c: &Config, mesh: bool) -> std::result::Result<(), ConfigError> {
    for o in OPTIONS.iter().filter(|o| mesh || o.scope == Scope::Octree) {
        if let (Some((range, value)), Some(key)) = (&o.range, o.keys.first()) {
            if let Some(v) = value(c) {
                range.check(v).map_err(|m| ConfigError::new(key, m))?;
            }
        }
    }
    Ok(())
}

/// Checks `value` against the declared range of `key`, naming it `label`
/// (the C API's settings, by their argument names).
pub fn check_key(key: &str, label: &str, value: f64) -> Result<()> {
    match entry(key).and_then(|o| o.range.as_ref()) {
        Some((range, _)) => range
            .check(value)
            .map_err(|m| Error::invalid(format!("{label} {m}"))),
        None => Ok(()),
    }
}

/// Checks the snap's options against the declared ranges of the
/// `mesh.snap_*` keys.
pub fn check_snap(o: &crate::mesh::snap::SnapOptions) -> Result<()> {
    check_key(
        "mesh.snap_feature_angle",
        "the snap feature angle",
        o.feature_angle_deg,
    )?;
    check_key("mesh.snap_layers", "the snap layers", o.layers.into())?;
    check_key(
        "mesh.snap_iterations",
        "the snap iterations",
        o.iterations.into(),
    )?;
    check_key(
        "mesh.snap_min_jacobian",
        "the snap's least scaled Jacobian",
        o.min_jacobian,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snap_options_are_checked_against_the_declared_ranges() {
        use crate::mesh::snap::SnapOptions;
        assert!(check_snap(&SnapOptions::default()).is_ok());
        for bad in [
            SnapOptions {
                feature_angle_deg: 200.0,
                ..SnapOptions::default()
            },
            SnapOptions {
                feature_angle_deg: f64::NAN,
                ..SnapOptions::default()
            },
            SnapOptions {
                min_jacobian: 0.0,
                ..SnapOptions::default()
            },
            SnapOptions {
                iterations: 1001,
                ..SnapOptions::default()
            },
        ] {
            assert!(check_snap(&bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn every_key_is_a_field_and_every_field_a_key() {
        let mut c = Config::default();
        c.surface.file = "sphere".into();
        c.regions = vec![Region::parse("box:0,0,0,1,1,1:5").unwrap()];
        // Every Option set, so that the TOML holds every field.
        let o = &mut c.octree;
        (o.level, o.max_level, o.feature_angle) = (Some(4), Some(5), Some(20.0));
        (o.size, o.max_size, o.min_size) = (Some(1.0), Some(0.5), Some(2.0));
        o.surface_levels.insert("a".into(), [1, 2]);
        o.distance = vec![(0.1, 3)];
        o.distance_size = vec![(0.1, 0.2)];
        (o.max_octants, o.memory_budget) = (Some(9), Some(ByteSize(1 << 30)));
        c.surface.others = vec!["torus".into()];
        c.domain = DomainConfig {
            fit: Some(0.5),
            cube: Some([0.0; 4]),
            bbox: Some([0.0; 6]),
            roots: Some([1, 1, 1]),
        };
        c.classify.inside = Some(InsideRule::Auto);
        (c.leak.inside_point, c.leak.path) = (Some([0.0; 3]), Some("l".into()));
        c.mesh.patches.insert("a".into(), "b".into());
        (c.mesh.clean_walls, c.mesh.snap_min_jacobian) = (Some(true), Some(0.1));
        (c.mesh.layers, c.mesh.first_layer) = (Some(3), Some(0.1));
        (c.mesh.final_layer, c.mesh.layer_thickness) = (Some(0.2), Some(0.3));
        c.layers = vec![super::super::PatchLayers::default()];
        let out = &mut c.output;
        (out.stats, out.leaves, out.refined_leaves) =
            (Some("s".into()), Some("l".into()), Some("r".into()));
        (out.gmsh, out.abaqus) = (Some("g.msh".into()), Some("a.inp".into()));
        (out.save, c.octree.load) = (Some("s.ckpt".into()), Some("l.ckpt".into()));
        (out.exodus, out.cgns) = (Some("e.exo".into()), Some("c.cgns".into()));
        (out.vtu, out.openfoam, out.quality_out, out.quality_worst) = (
            Some("v".into()),
            Some("f".into()),
            Some("q".into()),
            Some(3),
        );
        let full: toml::Table = toml::from_str(&c.to_toml()).unwrap();
        let mut fields = Vec::new();
        for (table, t) in &full {
            match t.as_table() {
                Some(t) => fields.extend(t.keys().map(|f| format!("{table}.{f}"))),
                None => fields.push(table.clone()),
            }
        }
        let mut declared: Vec<String> = keys().map(str::to_string).collect();
        fields.sort();
        declared.sort();
        assert_eq!(fields, declared);
    }

    #[test]
    fn defaults_and_ranges_read_well() {
        let d = |k: &str| entry(k).unwrap().default_text();
        assert_eq!(d("mesh.snap_layers").as_deref(), Some("2"));
        assert_eq!(d("mesh.snap_feature_angle").as_deref(), Some("30"));
        assert_eq!(d("octree.balance").as_deref(), Some("corner"));
        assert_eq!(d("domain.fit").as_deref(), Some("0.7"));
        assert_eq!(d("octree.feature_angle").as_deref(), Some("30"));
        assert_eq!(d("octree.level"), None);
        let r = entry("domain.fit").unwrap().range.unwrap().0;
        assert_eq!(r.to_string(), "(0, 1]");
        assert_eq!(r.complaint(1.5), "must be in (0, 1], got 1.5");
        assert!(!r.contains(f64::NAN) && r.contains(1.0) && !r.contains(0.0));
        // Switches and repeatable options have no default value to show.
        for o in OPTIONS {
            if matches!(o.kind, Kind::Switch | Kind::Many) {
                assert!(o.default_text().is_none(), "{}", o.name);
            }
        }
    }
}
