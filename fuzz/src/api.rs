//! Fuzz body `api`: an arbitrary byte string decoded into a sequence of C
//! API calls (`octmesh::internals::ffi`) with arbitrary arguments on `MPI_COMM_SELF`:
//! handles created and destroyed, options and domains with NaN, negative
//! and huge numbers, surfaces from random triangles, built-in shapes and
//! STL bytes, refinement by surface and by callback with random levels and
//! limits, balance, partition (with extreme weights), meshes with random
//! keep and cut rules, every getter with NULL or valid out-pointers, VTU
//! output. Any status is acceptable except `OCTMESH_STATUS_INTERNAL` (a
//! caught panic or a broken invariant); a crash, a hang or a handle left
//! behind is a failure. What the getters return is checked against the
//! documented ranges.
//!
//! Encoding: each call takes one byte for the function, then the bytes its
//! arguments need (see [`run`]); missing bytes read as zero and the input
//! ends after [`MAX_CALLS`] calls. Levels are kept small (at most 4 unless
//! the handle has an octant limit of at most [`SMALL_LIMIT`]) so that an
//! input runs in milliseconds.

use std::ffi::{c_char, c_void, CStr, CString};
use std::path::PathBuf;
use std::ptr::{null, null_mut};

use octmesh::internals::ffi::handle::*;
use octmesh::internals::ffi::mesh::*;
use octmesh::internals::ffi::octree::*;
use octmesh::internals::ffi::surface::*;
use octmesh::internals::ffi::*;

/// Calls per input.
pub const MAX_CALLS: usize = 48;

/// Handles with a limit at most this large may refine to any level.
pub const SMALL_LIMIT: i64 = 20_000;

/// Initialises MPI once per process (a singleton without `mpirun`); it is
/// never finalised, as the process may run many inputs.
pub fn init_mpi() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let mut flag = 0;
        // SAFETY: MPI_Initialized may be called at any time; MPI_Init once.
        unsafe {
            mpi_sys::MPI_Initialized(&mut flag);
            if flag == 0 {
                let rc = mpi_sys::MPI_Init(null_mut(), null_mut());
                assert_eq!(rc, 0, "MPI_Init failed");
            }
        }
    });
}

struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Bytes<'_> {
    fn done(&self) -> bool {
        self.pos >= self.data.len()
    }

    fn u8(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }

    fn u64(&mut self) -> u64 {
        u64::from(self.u32()) | (u64::from(self.u32()) << 32)
    }

    /// One chance in `n` (n > 0).
    fn one_in(&mut self, n: u8) -> bool {
        self.u8().is_multiple_of(n)
    }

    /// A double: mostly small numbers on a 1/64 grid, sometimes a special
    /// value or raw bits.
    fn f64(&mut self) -> f64 {
        match self.u8() {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => 0.0,
            4 => -0.0,
            5 => 1e300,
            6 => -1e300,
            7 => 1e-300,
            8 => f64::MIN_POSITIVE,
            9 => f64::from_bits(self.u64()),
            10 => 1.0,
            11 => -1.0,
            _ => f64::from(self.u16() as i16) / 64.0,
        }
    }

    fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }

    /// A level: small valid ones, any valid one when `any`, or out of range.
    fn level(&mut self, any: bool) -> i32 {
        match self.u8() {
            b @ 0..=199 => i32::from(b % if any { 19 } else { 5 }),
            200..=209 => -1,
            210..=219 => 19,
            220..=229 => i32::MIN,
            230..=239 => i32::MAX,
            b => i32::from(b),
        }
    }

    /// An enumeration value: mostly in `0..n`, sometimes anything.
    fn choice(&mut self, n: u8) -> i32 {
        let b = self.u8();
        if b >= 240 {
            self.u32() as i32
        } else {
            i32::from(b % (n + 1)) - 1
        }
    }
}

/// The per-handle facts the decoder needs to keep calls cheap.
struct Slot {
    h: *mut octmesh_t,
    small_limit: bool,
}

struct State {
    slots: [Option<Slot>; 2],
    dir: PathBuf,
}

impl State {
    /// A handle (or NULL, one time in 16) from slot `b`.
    fn handle(&self, b: u8) -> *mut octmesh_t {
        if b % 16 == 15 {
            return null_mut();
        }
        self.slots[(b % 2) as usize]
            .as_ref()
            .map_or(null_mut(), |s| s.h)
    }

    fn small_limit(&self, b: u8) -> bool {
        self.slots[(b % 2) as usize]
            .as_ref()
            .is_some_and(|s| s.small_limit)
    }
}

fn ok(s: octmesh_status_t) -> bool {
    s == octmesh_status_t::OCTMESH_STATUS_OK
}

/// The status must be one of the documented ones and not INTERNAL; a
/// failed call on a handle must leave a message.
fn check_status(s: octmesh_status_t, h: *const octmesh_t, what: &str) {
    assert_ne!(
        s,
        octmesh_status_t::OCTMESH_STATUS_INTERNAL,
        "{what}: internal error: {}",
        last_error(h)
    );
    if !ok(s) {
        let msg = last_error(h);
        assert!(!msg.is_empty(), "{what}: {s:?} without a message");
    }
}

fn last_error(h: *const octmesh_t) -> String {
    // SAFETY: NULL or a live handle; the result is a valid C string.
    unsafe { CStr::from_ptr(octmesh_last_error(h)) }
        .to_string_lossy()
        .into_owned()
}

fn mix(mut x: u64) -> u64 {
    x ^= x >> 33;
    x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
    x ^= x >> 33;
    x = x.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    x ^ (x >> 33)
}

fn octant_hash(seed: u64, o: &octmesh_octant_t) -> u64 {
    mix(seed ^ mix(o.x as u64 | (o.y as u64) << 21 | (o.z as u64) << 42) ^ (o.level as u64) << 58)
}

unsafe extern "C" fn refine_cb(ctx: *mut c_void, o: *const octmesh_octant_t) -> bool {
    // SAFETY: ctx points to the seed, o to a valid octant (the library's
    // contract).
    let (seed, o) = unsafe { (*(ctx as *const u64), &*o) };
    // The low byte of the seed sets the share of octants refined.
    octant_hash(seed, o) % 256 < seed % 256
}

unsafe extern "C" fn weight_cb(ctx: *mut c_void, o: *const octmesh_octant_t) -> u64 {
    // SAFETY: as in `refine_cb`.
    let (seed, o) = unsafe { (*(ctx as *const u64), &*o) };
    match seed % 6 {
        0 => 0,
        1 => 1,
        2 => 1 + o.level as u64,
        3 => u64::MAX,
        4 => octant_hash(seed, o) >> 40,
        _ => octant_hash(seed, o),
    }
}

fn scratch_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("octmesh-fuzz-api-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&d);
    d
}

fn cstring(p: &std::path::Path) -> CString {
    CString::new(p.to_string_lossy().as_bytes()).expect("no NUL in the scratch path")
}

/// Runs one input; every handle it creates is destroyed before it returns.
pub fn run(data: &[u8]) {
    init_mpi();
    let mut st = State {
        slots: [None, None],
        dir: scratch_dir(),
    };
    let mut b = Bytes { data, pos: 0 };
    for _ in 0..MAX_CALLS {
        if b.done() {
            break;
        }
        call(&mut st, &mut b);
    }
    for s in st.slots.iter_mut() {
        if let Some(s) = s.take() {
            // The C API's contract: a live handle, destroyed once.
            octmesh_destroy(s.h);
        }
    }
}

fn call(st: &mut State, b: &mut Bytes) {
    let op = b.u8();
    let hb = b.u8();
    let h = st.handle(hb);
    // SAFETY (all calls below): handles are live or NULL, pointers are
    // NULL or valid for the documented number of elements.
    unsafe {
        match op % 18 {
            0 => create(st, b, hb),
            1 => {
                let slot = &mut st.slots[(hb % 2) as usize];
                if let Some(s) = slot.take() {
                    octmesh_destroy(s.h);
                } else {
                    octmesh_destroy(null_mut());
                }
            }
            2 => {
                let origin = [b.f64(), b.f64(), b.f64()];
                let p = if b.one_in(8) { null() } else { origin.as_ptr() };
                let s = octmesh_domain_set(h, p, b.f64());
                check_status(s, h, "set_domain");
            }
            3 => {
                let mut origin = [f64::NAN; 3];
                let mut side = f64::NAN;
                let (po, ps) = match b.u8() % 4 {
                    0 => (null_mut(), &mut side as *mut f64),
                    1 => (origin.as_mut_ptr(), null_mut()),
                    _ => (origin.as_mut_ptr(), &mut side as *mut f64),
                };
                let s = octmesh_domain_get(h, po, ps);
                check_status(s, h, "get_domain");
                if ok(s) {
                    assert!(side.is_finite() && side > 0.0, "side {side}");
                    assert!(origin.iter().all(|c| c.is_finite()));
                }
            }
            4 => {
                let ntri = match b.u8() {
                    0..=199 => 1 + i64::from(b.u8() % 8),
                    200..=219 => 0,
                    220..=239 => -1,
                    _ => i64::MIN,
                };
                // xyz always holds 9 ntri values (at least 9: a count of 0
                // or less must be refused before anything is read).
                let n = ntri.clamp(1, 8) as usize;
                let xyz: Vec<f64> = (0..9 * n).map(|_| b.f64()).collect();
                let p = if b.one_in(16) { null() } else { xyz.as_ptr() };
                let s = octmesh_surface_from_triangles(h, ntri, p);
                check_status(s, h, "surface_from_triangles");
            }
            5 => {
                let names: [&CStr; 5] = [c"sphere", c"torus", c"cube", c"", c"sphere "];
                let k = b.u8() % 6;
                let p = if k == 5 {
                    null()
                } else {
                    names[k as usize].as_ptr()
                };
                let s = octmesh_surface_builtin(h, p);
                check_status(s, h, "surface_builtin");
            }
            6 => {
                let path = match b.u8() % 5 {
                    0 => None,
                    1 => Some(CString::default()),
                    2 => Some(cstring(&st.dir.join("missing.stl"))),
                    3 => Some(cstring(&st.dir)),
                    _ => {
                        let len = usize::from(b.u16() % 600);
                        let start = b.pos.min(b.data.len());
                        let end = (start + len).min(b.data.len());
                        let file = st.dir.join("input.stl");
                        let _ = std::fs::write(&file, &b.data[start..end]);
                        b.pos = end;
                        Some(cstring(&file))
                    }
                };
                let p = path.as_ref().map_or(null(), |c| c.as_ptr());
                let s = octmesh_surface_from_stl(h, p);
                check_status(s, h, "surface_from_stl");
            }
            7 => {
                let level = b.level(st.small_limit(hb));
                let before = leaves_of(h);
                let s = octmesh_octree_refine_surface(h, level);
                check_status(s, h, "refine_surface");
                if !ok(s) {
                    assert_eq!(
                        leaves_of(h),
                        before,
                        "a failed refinement changed the octree"
                    );
                }
            }
            8 => {
                let level = b.level(st.small_limit(hb));
                let seed = b.u64();
                let f: octmesh_refine_fn = if b.one_in(16) { None } else { Some(refine_cb) };
                let before = leaves_of(h);
                let ctx = &seed as *const u64 as *mut c_void;
                let s = octmesh_octree_refine_callback(h, level, f, ctx);
                check_status(s, h, "refine_callback");
                if !ok(s) {
                    assert_eq!(
                        leaves_of(h),
                        before,
                        "a failed refinement changed the octree"
                    );
                }
            }
            9 => {
                let before = leaves_of(h);
                let s = octmesh_octree_balance(h, b.choice(4));
                check_status(s, h, "balance");
                if !ok(s) {
                    assert_eq!(leaves_of(h), before, "a failed balance changed the octree");
                }
            }
            10 => {
                let seed = b.u64();
                let f: octmesh_weight_fn = if b.one_in(2) { None } else { Some(weight_cb) };
                let ctx = &seed as *const u64 as *mut c_void;
                let n = leaves_of(h).map_or(0, |v| v.len());
                let s = octmesh_octree_partition(h, f, ctx);
                check_status(s, h, "partition");
                if f.is_some() && seed % 6 == 3 && n >= 2 {
                    // Weights of u64::MAX: the sum cannot fit.
                    assert_eq!(s, octmesh_status_t::OCTMESH_STATUS_INVALID_ARGUMENT);
                }
            }
            11 => {
                let s = octmesh_mesh_build(h, b.choice(3), b.choice(3));
                check_status(s, h, "mesh");
                if ok(s) {
                    check_mesh(h);
                }
            }
            12 => {
                let (mut l, mut g) = (-1i32, -1i64);
                let (pl, pg) = match b.u8() % 4 {
                    0 => (null_mut(), &mut g as *mut i64),
                    1 => (&mut l as *mut i32, null_mut()),
                    _ => (&mut l as *mut i32, &mut g as *mut i64),
                };
                let s = octmesh_octree_get_num_leaves(h, pl, pg);
                check_status(s, h, "get_num_leaves");
                if ok(s) {
                    assert!(l >= 1 && l as i64 == g, "{l} leaves of {g} on one rank");
                    check_leaves(h, l as usize, b.one_in(8));
                }
            }
            13 => {
                let mut c = octmesh_mesh_counts_t::default();
                let p = if b.one_in(8) {
                    null_mut()
                } else {
                    &mut c as *mut _
                };
                let s = octmesh_mesh_get_counts(h, p);
                check_status(s, h, "mesh_get_counts");
                if ok(s) {
                    check_mesh(h);
                }
            }
            14 => write_vtu(st, b, h),
            15 => {
                let _ = last_error(if b.one_in(2) { null() } else { h });
            }
            16 => {
                let s = CStr::from_ptr(octmesh_status_name(b.u32() as i32));
                assert!(s.to_bytes().starts_with(b"OCTMESH_STATUS_"));
            }
            _ => {
                let mut o = octmesh_options_t::default();
                let p = if b.one_in(4) {
                    null_mut()
                } else {
                    &mut o as *mut _
                };
                let s = octmesh_options_default(p);
                assert_eq!(ok(s), !p.is_null());
            }
        }
    }
}

/// Creates a handle in slot `hb % 2` (destroying the one there).
unsafe fn create(st: &mut State, b: &mut Bytes, hb: u8) {
    let mut opts = octmesh_options_t::default();
    let limits = [0, 1, 8, 100, 1000, 5000, SMALL_LIMIT, 1 << 40, i64::MAX];
    opts.fit = if b.one_in(2) { 0.7 } else { b.f64() };
    opts.max_octants = limits[(b.u8() % 9) as usize];
    let popts = if b.one_in(4) {
        null()
    } else {
        &opts as *const _
    };
    // SAFETY: reading MPI constants.
    let comm = unsafe {
        if b.one_in(16) {
            mpi_sys::RSMPI_COMM_NULL
        } else {
            mpi_sys::RSMPI_COMM_SELF
        }
    };
    let mut out: *mut octmesh_t = null_mut();
    let pout = if b.one_in(16) {
        null_mut()
    } else {
        &mut out as *mut _
    };
    // The C API's contract: valid or NULL pointers.
    let s = octmesh_create(comm, popts, pout);
    check_status(s, null(), "create");
    if ok(s) {
        assert!(!out.is_null());
        let small = !popts.is_null() && (1..=SMALL_LIMIT).contains(&opts.max_octants);
        let slot = &mut st.slots[(hb % 2) as usize];
        if let Some(old) = slot.take() {
            // The C API's contract: a live handle, destroyed once.
            octmesh_destroy(old.h);
        }
        *slot = Some(Slot {
            h: out,
            small_limit: small,
        });
    } else {
        assert!(out.is_null(), "create wrote its out-parameter on failure");
    }
}

/// The local leaves of `h`, or None without an octree.
fn leaves_of(h: *mut octmesh_t) -> Option<Vec<octmesh_octant_t>> {
    let (mut l, mut g) = (0i32, 0i64);
    // The C API's contract: valid out-pointers.
    if !ok(octmesh_octree_get_num_leaves(h, &mut l, &mut g)) {
        return None;
    }
    let mut v = vec![
        octmesh_octant_t {
            x: -1,
            y: -1,
            z: -1,
            level: -1
        };
        l as usize
    ];
    // The C API's contract: room for the local leaves.
    let s = octmesh_octree_get_leaves(h, v.as_mut_ptr(), l);
    assert!(ok(s));
    Some(v)
}

/// The leaves tile the root cube in Morton order.
fn check_leaves(h: *mut octmesh_t, n: usize, null_out: bool) {
    if null_out {
        // The C API's contract: NULL is refused before anything is written.
        let s = octmesh_octree_get_leaves(h, null_mut(), n as i32);
        assert_eq!(s, octmesh_status_t::OCTMESH_STATUS_INVALID_ARGUMENT);
        return;
    }
    let v = leaves_of(h).expect("leaves");
    assert_eq!(v.len(), n);
    let mut volume: u128 = 0;
    for o in &v {
        assert!((0..=18).contains(&o.level), "{o:?}");
        let side = 1i64 << (19 - o.level);
        for c in [o.x, o.y, o.z] {
            assert!(c >= 0 && i64::from(c) % side == 0 && i64::from(c) + side <= 1 << 19);
        }
        volume += (side as u128).pow(3);
    }
    assert_eq!(volume, 1u128 << 57, "the leaves do not fill the cube");
}

/// Reads every mesh array with its documented length and checks ranges.
fn check_mesh(h: *mut octmesh_t) {
    let mut c = octmesh_mesh_counts_t::default();
    // SAFETY (whole function): valid out-pointers; arrays are read within
    // the documented lengths.
    unsafe {
        assert!(ok(octmesh_mesh_get_counts(h, &mut c)));
        assert!(c.local_elements >= 0 && c.local_elements as i64 == c.global_elements);
        assert!(0 <= c.num_owned && c.num_owned <= c.num_independent);
        assert!(c.num_independent <= c.local_nodes);
        assert_eq!(
            c.num_owned as i64, c.global_independent,
            "one rank owns everything"
        );
        assert_eq!(
            (c.local_nodes - c.num_independent) as i64,
            c.global_face_hanging + c.global_edge_hanging
        );
        let (ne, nn, ni) = (
            c.local_elements as usize,
            c.local_nodes as usize,
            c.num_independent as usize,
        );
        let mut conn: *const i32 = null();
        assert!(ok(octmesh_mesh_get_connectivity(h, &mut conn)));
        if ne > 0 {
            let conn = std::slice::from_raw_parts(conn, 8 * ne);
            assert!(conn.iter().all(|&n| n >= 0 && (n as usize) < nn));
        }
        let mut xyz: *const f64 = null();
        assert!(ok(octmesh_mesh_get_coordinates(h, &mut xyz)));
        if nn > 0 {
            let xyz = std::slice::from_raw_parts(xyz, 3 * nn);
            assert!(xyz.iter().all(|x| x.is_finite()));
        }
        let mut gid: *const i64 = null();
        assert!(ok(octmesh_mesh_get_global_ids(h, &mut gid)));
        let mut owners: *const i32 = null();
        assert!(ok(octmesh_mesh_get_owners(h, &mut owners)));
        if ni > 0 {
            let gid = std::slice::from_raw_parts(gid, ni);
            let owners = std::slice::from_raw_parts(owners, ni);
            let mut seen = vec![false; ni];
            for (&g, &o) in gid.iter().zip(owners) {
                assert!(g >= 0 && (g as usize) < ni && !seen[g as usize]);
                seen[g as usize] = true;
                assert_eq!(o, 0);
            }
        }
        let (mut soff, mut sranks): (*const i32, *const i32) = (null(), null());
        assert!(ok(octmesh_mesh_get_sharers(h, &mut soff, &mut sranks)));
        let soff = std::slice::from_raw_parts(soff, ni + 1);
        assert!(soff.iter().enumerate().all(|(i, &o)| o as usize == i));
        let mut nnb = -1;
        let (mut r, mut o, mut n): (*const i32, *const i32, *const i32) = (null(), null(), null());
        assert!(ok(octmesh_mesh_get_exchange(
            h, &mut nnb, &mut r, &mut o, &mut n
        )));
        assert_eq!(nnb, 0);
        let (mut hc, mut hd): (*const i32, *const i32) = (null(), null());
        assert!(ok(octmesh_mesh_get_hanging(h, &mut hc, &mut hd)));
        let nh = nn - ni;
        if nh > 0 {
            let hc = std::slice::from_raw_parts(hc, nh);
            let hd = std::slice::from_raw_parts(hd, 4 * nh);
            for (k, &cnt) in hc.iter().enumerate() {
                assert!(cnt == 2 || cnt == 4);
                for j in 0..4 {
                    let d = hd[4 * k + j];
                    if j < cnt as usize {
                        assert!(d >= 0 && (d as usize) < ni);
                    } else {
                        assert_eq!(d, -1);
                    }
                }
            }
        }
        let (mut cls, mut lvl): (*const i8, *const i8) = (null(), null());
        assert!(ok(octmesh_mesh_get_element_class(h, &mut cls)));
        assert!(ok(octmesh_mesh_get_element_level(h, &mut lvl)));
        if ne > 0 {
            let cls = std::slice::from_raw_parts(cls, ne);
            let lvl = std::slice::from_raw_parts(lvl, ne);
            assert!(cls.iter().all(|&k| (0..=2).contains(&k)));
            assert!(lvl.iter().all(|&l| (0..=18).contains(&l)));
        }
        let s = octmesh_mesh_get_connectivity(h, null_mut());
        assert_eq!(s, octmesh_status_t::OCTMESH_STATUS_INVALID_ARGUMENT);
    }
}

/// VTU output with 0 to 2 point fields, some of them invalid.
unsafe fn write_vtu(st: &mut State, b: &mut Bytes, h: *mut octmesh_t) {
    let good = cstring(&st.dir.join("out.pvtu"));
    let bad_dir = c"/nonexistent-octmesh-dir/x.pvtu";
    let path: *const c_char = match b.u8() % 6 {
        0 => null(),
        1 => c"".as_ptr(),
        2 => bad_dir.as_ptr(),
        3 => c"out.vtu".as_ptr(),
        _ => good.as_ptr(),
    };
    let mut c = octmesh_mesh_counts_t::default();
    // The C API's contract: valid out-pointer.
    let nodes = if ok(octmesh_mesh_get_counts(h, &mut c)) {
        Some(c.local_nodes as usize)
    } else {
        None
    };
    let field_names: [&CStr; 5] = [c"u", c"v", c"global_id", c"", c"u"];
    let nfields = b.choice(2); // -1, 0, 1 or 2 (or anything)
    let n = nfields.clamp(0, 2) as usize;
    let names: Vec<*const c_char> = (0..n)
        .map(|_| {
            let k = b.u8() % 6;
            if k == 5 {
                null()
            } else {
                field_names[k as usize].as_ptr()
            }
        })
        .collect();
    let arrays: Vec<Vec<f64>> = (0..n).map(|_| vec![b.f64(); nodes.unwrap_or(0)]).collect();
    // Values only where their length is known to be right.
    let values: Vec<*const f64> = arrays
        .iter()
        .map(|a| if nodes.is_some() { a.as_ptr() } else { null() })
        .collect();
    let (pn, pv) = if b.one_in(8) {
        (null(), null())
    } else {
        (names.as_ptr(), values.as_ptr())
    };
    if nodes.is_none() && n > 0 && !pv.is_null() {
        // Without a mesh the call must fail before reading the values.
        // The C API's contract: valid pointers; the values are NULL.
        let s = octmesh_mesh_write_vtu_fields(h, path, n as i32, pn, pv);
        check_status(s, h, "write_vtu_fields");
        assert!(!ok(s));
        return;
    }
    // nfields beyond the arrays' length would make the library read past
    // them: pass the number of arrays unless it is the negative case.
    let nf = if nfields < 0 { nfields } else { n as i32 };
    // The C API's contract: valid pointers with `n` entries.
    let s = octmesh_mesh_write_vtu_fields(h, path, nf, pn, pv);
    check_status(s, h, "write_vtu_fields");
}
