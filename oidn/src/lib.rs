//! Run-time binding to Intel Open Image Denoise 2.x (OIDN), throng's denoiser.
//!
//! # What it binds
//!
//! The CPU device and the `RT` filter of OIDN's C API (`oidnNewDevice`, `oidnNewFilter`,
//! `oidnSetSharedFilterImage`, `oidnCommitFilter`, `oidnExecuteFilter`, ...), on f32 RGB planes:
//! interleaved RGB, row-major, `width * height * 3` floats, no padding. On top of that it offers
//! the three filters a path tracer's final frame wants:
//!
//! * [`Device::prefilter_albedo`] and [`Device::prefilter_normal`]: denoise the noisy auxiliary
//!   (guide) images once;
//! * [`Device::denoise`]: denoise a beauty (`hdr`) image with the clean guides (`cleanAux`);
//! * [`Denoiser`]: the same, reusable: it keeps the clean guides and one committed beauty filter,
//!   so the many passes of one image (light groups, AOVs) pay for the guides and the filter's
//!   set-up once.
//!
//! This crate is the one place in throng with `unsafe` code (the `throng` library and the CLI
//! are `#![forbid(unsafe_code)]`). Every unsafe block is an FFI call or a symbol look-up and
//! carries a `// SAFETY:` comment; all sizes are validated in safe code before any FFI call, and
//! every image handed to OIDN is a heap buffer owned by the filter's Rust wrapper, so OIDN never
//! sees a pointer that can dangle or alias a caller's slice.
//!
//! # Why run-time loading
//!
//! OIDN is a 170 MB native library (oneDNN-style kernels, TBB) that most machines building
//! throng do not have. Linking it would make `cargo build` and `cargo test` fail there, so it is
//! opened with `dlopen` ([`libloading`]) when first asked for, and the README's two commands
//! (`cargo run -- demo`, `cargo test --locked`) build and pass on a machine without it: the OIDN
//! tests print that they were skipped unless `THRONG_REQUIRE_OIDN=1` (CI sets it, and installs
//! OIDN). Nothing is opened until [`Library::find`] is called.
//!
//! The official 2.5.1 binaries come in the PyPI wheel `pyoidn`; from the throng checkout,
//!
//! ```text
//! python3 -m pip install --no-deps --target .oidn pyoidn==2.5.1.0
//! ```
//!
//! puts them in `.oidn/pyoidn/oidn/lib/` (171 MB, no numpy needed, git-ignored), where
//! [`Library::find`] looks. Or point `THRONG_OIDN` at any OIDN 2.x `lib` folder or at its
//! `libOpenImageDenoise.so.2`. The search order is in [`Library::find`].
//!
//! # What is deterministic
//!
//! On one machine, OIDN's CPU output is bit-identical from run to run and across thread counts
//! (`num_threads` 1, 2, ...): its kernels split work by tiles, not by reduction order, and the
//! tests check both. It is NOT promised across CPU instruction sets: OIDN picks its tensor
//! layout and kernels by ISA (AVX2, AVX-512, AMX), so an AVX2 machine and an AVX-512 machine
//! give slightly different floats. `max_memory_mb` can change the tiling and so the result too.
//! Golden images of denoised output must therefore be compared with a tolerance across machines.
//!
//! # Cost
//!
//! Each filter (albedo prefilter, normal prefilter, HDR beauty with clean guides) costs about the
//! same; [`Denoiser`] keeps the prefiltered guides and its committed filter, so the many passes of
//! one image pay for the guides once (two of the three filters). Measured figures:
//! docs/benchmarks.md, "Denoising".
//!
//! # Example
//!
//! ```no_run
//! use throng_oidn::{Denoiser, Device, DeviceOptions, Library, Options};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let (w, h) = (64, 32);
//! let (albedo, normal) = (vec![0.5f32; w * h * 3], vec![0.0f32; w * h * 3]);
//! let lib = Library::find(None)?;
//! let device = Device::new(lib, DeviceOptions::default())?;
//! // Prefilter the guides once, then denoise every pass of the image with them.
//! let mut denoiser = Denoiser::prefiltered(&device, w, h, Some(&albedo), Some(&normal), Options::default())?;
//! for pass in [vec![1.0f32; w * h * 3], vec![2.0f32; w * h * 3]] {
//!     let clean: Vec<f32> = denoiser.denoise(&pass)?;
//!     assert_eq!(clean.len(), w * h * 3);
//! }
//! # Ok(()) }
//! ```

#![deny(clippy::undocumented_unsafe_blocks, missing_docs)]

use std::ffi::{c_char, c_void, CStr};
use std::fmt;
use std::mem::ManuallyDrop;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

/// The pip command that installs OIDN where [`Library::find`] looks (run from the throng checkout).
pub const PIP_INSTALL: &str = "python3 -m pip install --no-deps --target .oidn pyoidn==2.5.1.0";

/// The oldest OIDN this crate accepts, as OIDN reports it (`major * 10000 + minor * 100 + patch`).
pub const MIN_VERSION: i32 = 20000;

/// The file dlopen'd: OIDN 2.x's soname on this platform.
#[cfg(target_os = "linux")]
pub const LIB_NAME: &str = "libOpenImageDenoise.so.2";
/// The file dlopen'd: OIDN 2.x's install name on this platform.
#[cfg(target_os = "macos")]
pub const LIB_NAME: &str = "libOpenImageDenoise.2.dylib";
/// The file dlopen'd: OIDN's DLL on this platform.
#[cfg(windows)]
pub const LIB_NAME: &str = "OpenImageDenoise.dll";
/// The file dlopen'd (assumed ELF-like elsewhere).
#[cfg(not(any(target_os = "linux", target_os = "macos", windows)))]
pub const LIB_NAME: &str = "libOpenImageDenoise.so.2";

/// Files opened by absolute path from the library's folder when the library alone fails to load:
/// the wheel's RPATH is `$ORIGIN/../lib`, which only finds its neighbours when the folder is named
/// `lib`. Once loaded by path, the dynamic linker matches them by soname.
#[cfg(target_os = "linux")]
const PRELOAD_PREFIXES: &[&str] = &["libtbb.so.12", "libOpenImageDenoise_core.so."];
#[cfg(not(target_os = "linux"))]
const PRELOAD_PREFIXES: &[&str] = &[];

// ---------------------------------------------------------------------------------------------
// Raw C API (OIDN 2.x, include/OpenImageDenoise/oidn.h)
// ---------------------------------------------------------------------------------------------

type RawDevice = *mut c_void; // OIDNDevice
type RawFilter = *mut c_void; // OIDNFilter
const OIDN_DEVICE_TYPE_CPU: i32 = 1;
const OIDN_FORMAT_FLOAT3: i32 = 3;
const OIDN_ERROR_NAMES: [&str; 7] =
    ["NONE", "UNKNOWN", "INVALID_ARGUMENT", "INVALID_OPERATION", "OUT_OF_MEMORY", "UNSUPPORTED_HARDWARE", "CANCELLED"];

/// The entry points used, resolved once. The libraries they live in are never unloaded.
struct Api {
    path: PathBuf,
    version: i32,
    new_device: unsafe extern "C" fn(i32) -> RawDevice,
    set_device_bool: unsafe extern "C" fn(RawDevice, *const c_char, bool),
    set_device_int: unsafe extern "C" fn(RawDevice, *const c_char, i32),
    get_device_int: unsafe extern "C" fn(RawDevice, *const c_char) -> i32,
    commit_device: unsafe extern "C" fn(RawDevice),
    get_device_error: unsafe extern "C" fn(RawDevice, *mut *const c_char) -> i32,
    release_device: unsafe extern "C" fn(RawDevice),
    new_filter: unsafe extern "C" fn(RawDevice, *const c_char) -> RawFilter,
    #[allow(clippy::type_complexity)]
    set_shared_filter_image:
        unsafe extern "C" fn(RawFilter, *const c_char, *mut c_void, i32, usize, usize, usize, usize, usize),
    set_filter_bool: unsafe extern "C" fn(RawFilter, *const c_char, bool),
    set_filter_int: unsafe extern "C" fn(RawFilter, *const c_char, i32),
    set_filter_float: unsafe extern "C" fn(RawFilter, *const c_char, f32),
    commit_filter: unsafe extern "C" fn(RawFilter),
    execute_filter: unsafe extern "C" fn(RawFilter),
    release_filter: unsafe extern "C" fn(RawFilter),
}

impl Api {
    /// Opens `path` (after its folder's [`PRELOAD_PREFIXES`]), resolves the entry points and probes
    /// a CPU device for the version. Whatever is opened is never closed, success or not: OIDN and
    /// TBB start threads and load device modules that must never see their code unmapped.
    fn open(path: &Path) -> Result<Api, String> {
        // SAFETY: loading runs the library's initialisers; the file is the OIDN 2.x library the
        // caller or the search named, whose initialisers only set up its own state.
        let first = unsafe { libloading::Library::new(path) };
        let lib = match first {
            Ok(lib) => lib,
            Err(e) => {
                // Its neighbours may be missing from the linker's view (folder not named `lib`):
                // open them by absolute path, then try again.
                let dir = path.parent().filter(|d| d.is_dir()).ok_or_else(|| format!("cannot load: {e}"))?;
                let deps: Vec<PathBuf> =
                    PRELOAD_PREFIXES.iter().filter_map(|p| first_file_with_prefix(dir, p)).collect();
                if deps.is_empty() {
                    return Err(format!("cannot load: {e}"));
                }
                for dep in deps {
                    // SAFETY: as above, for the TBB and OIDN core libraries shipped next to it.
                    let dep_lib = unsafe { libloading::Library::new(&dep) }
                        .map_err(|e2| format!("cannot load: {e}; nor its neighbour {}: {e2}", dep.display()))?;
                    std::mem::forget(dep_lib);
                }
                // SAFETY: as above.
                unsafe { libloading::Library::new(path) }
                    .map_err(|e2| format!("cannot load: {e}; after loading its neighbours: {e2}"))?
            }
        };
        let lib = ManuallyDrop::new(lib);
        macro_rules! sym {
            ($name:literal) => {
                // SAFETY: the field's type is the function's C signature in OIDN 2.x's oidn.h (the
                // version is checked right after), and the pointer is only used while `lib` is
                // loaded: forever, since it is never dropped (ManuallyDrop).
                *unsafe { lib.get(concat!($name, "\0").as_bytes()) }.map_err(|e| format!("lacks {}: {e}", $name))?
            };
        }
        let mut api = Api {
            path: path.to_path_buf(),
            version: 0,
            new_device: sym!("oidnNewDevice"),
            set_device_bool: sym!("oidnSetDeviceBool"),
            set_device_int: sym!("oidnSetDeviceInt"),
            get_device_int: sym!("oidnGetDeviceInt"),
            commit_device: sym!("oidnCommitDevice"),
            get_device_error: sym!("oidnGetDeviceError"),
            release_device: sym!("oidnReleaseDevice"),
            new_filter: sym!("oidnNewFilter"),
            set_shared_filter_image: sym!("oidnSetSharedFilterImage"),
            set_filter_bool: sym!("oidnSetFilterBool"),
            set_filter_int: sym!("oidnSetFilterInt"),
            set_filter_float: sym!("oidnSetFilterFloat"),
            commit_filter: sym!("oidnCommitFilter"),
            execute_filter: sym!("oidnExecuteFilter"),
            release_filter: sym!("oidnReleaseFilter"),
        };
        // Probe: a committed single-thread CPU device proves the CPU is supported and gives the version.
        let probe = RawDeviceHandle::new(&api, &DeviceOptions { num_threads: 1, set_affinity: false })
            .map(|d| d.version)
            .map_err(|e| format!("cannot create a CPU device: {e}"));
        api.version = probe?;
        if api.version < MIN_VERSION {
            return Err(format!("is OIDN version {}, throng needs {MIN_VERSION} (2.0.0) or newer", api.version));
        }
        Ok(api)
    }

    /// The first unqueried error on `dev` (or, for a null `dev`, this thread's global error).
    fn check(&self, dev: RawDevice, stage: &'static str) -> Result<(), DenoiseError> {
        let mut msg: *const c_char = std::ptr::null();
        // SAFETY: `dev` is null or a live device; `msg` is a valid out-pointer.
        let code = unsafe { (self.get_device_error)(dev, &mut msg) };
        if code == 0 {
            return Ok(());
        }
        let message = if msg.is_null() {
            String::new()
        } else {
            // SAFETY: OIDN returns a NUL-terminated string valid until the next API call on this
            // thread; it is copied at once.
            unsafe { CStr::from_ptr(msg) }.to_string_lossy().into_owned()
        };
        let name = OIDN_ERROR_NAMES.get(code as usize).copied().unwrap_or("UNKNOWN_CODE");
        Err(DenoiseError::Oidn { stage, code, name, message })
    }
}

fn first_file_with_prefix(dir: &Path, prefix: &str) -> Option<PathBuf> {
    let mut hits: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file() && p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(prefix)))
        .collect();
    hits.sort();
    hits.into_iter().next()
}

// ---------------------------------------------------------------------------------------------
// Library lookup
// ---------------------------------------------------------------------------------------------

/// The loaded OIDN library: cheap to copy, lives for the rest of the process.
#[derive(Clone, Copy)]
pub struct Library {
    api: &'static Api,
}

impl fmt::Debug for Library {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Library").field("path", &self.api.path).field("version", &self.api.version).finish()
    }
}

static LOADED: OnceLock<Api> = OnceLock::new();
static LOADING: Mutex<()> = Mutex::new(());

/// One place [`Library::find`] looked, and what it found there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Searched {
    /// Which rule produced the candidate, e.g. `"THRONG_OIDN"` or `"./.oidn"`.
    pub rule: &'static str,
    /// The candidate file (or, for the last rule, the bare soname handed to the dynamic linker).
    pub path: PathBuf,
    /// Why it was not used: `"not found"` or the loader's error.
    pub outcome: String,
}

/// [`Library::find`] found no usable OIDN 2.x; lists what it searched and says how to install it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FindError {
    /// Every candidate tried, in order.
    pub searched: Vec<Searched>,
}

impl fmt::Display for FindError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "Intel Open Image Denoise 2.x ({LIB_NAME}) not found or not usable; searched:")?;
        for s in &self.searched {
            writeln!(f, "  [{}] {}: {}", s.rule, s.path.display(), s.outcome)?;
        }
        write!(
            f,
            "Install it from the throng checkout with `{PIP_INSTALL}`, or set THRONG_OIDN to an OIDN 2.x lib folder or \
             to its {LIB_NAME}."
        )
    }
}

impl std::error::Error for FindError {}

impl Library {
    /// Finds and loads OIDN 2.x, probing a CPU device to check the version (>= [`MIN_VERSION`]).
    ///
    /// The first successful load is cached for the process and never unloaded; later calls return
    /// it whatever they are given. Each of `explicit` and `THRONG_OIDN` may be a file or a folder
    /// (the folder holding [`LIB_NAME`]). Search order:
    ///
    /// 1. `explicit`;
    /// 2. env `THRONG_OIDN`;
    /// 3. `$OIDN_DIR/lib`;
    /// 4. `.oidn/pyoidn/oidn/lib` (where [`PIP_INSTALL`] puts it) in the current directory, then in
    ///    every ancestor folder of the running executable (so `target/debug/throng` finds the
    ///    checkout's `.oidn`);
    /// 5. `pyoidn/oidn/lib` in `$VIRTUAL_ENV/lib/python3*/site-packages` and
    ///    `~/.local/lib/python3*/site-packages`;
    /// 6. plain `dlopen(LIB_NAME)` (the system's library path, `LD_LIBRARY_PATH`).
    ///
    /// If `explicit` or `THRONG_OIDN` is given, it alone is tried: asking for a library and getting
    /// another would be worse than an error.
    pub fn find(explicit: Option<&Path>) -> Result<Library, FindError> {
        if let Some(api) = LOADED.get() {
            return Ok(Library { api });
        }
        let _guard = LOADING.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(api) = LOADED.get() {
            return Ok(Library { api });
        }
        let mut searched = Vec::new();
        let pinned = match explicit {
            Some(p) => Some(("explicit path", p.to_path_buf())),
            None => {
                std::env::var_os("THRONG_OIDN").filter(|v| !v.is_empty()).map(|v| ("THRONG_OIDN", PathBuf::from(v)))
            }
        };
        let candidates = match pinned {
            Some((rule, p)) => vec![(rule, if p.is_dir() { p.join(LIB_NAME) } else { p })],
            None => search_candidates(),
        };
        for (rule, path) in candidates {
            // Rule 6 hands a bare name to the dynamic linker; every other candidate must exist.
            let bare = path.parent().is_none_or(|p| p.as_os_str().is_empty());
            if !bare && !path.is_file() {
                searched.push(Searched { rule, path, outcome: "not found".into() });
                continue;
            }
            match Api::open(&path) {
                Ok(api) => return Ok(Library { api: LOADED.get_or_init(|| api) }),
                Err(outcome) => searched.push(Searched { rule, path, outcome }),
            }
        }
        Err(FindError { searched })
    }

    /// The file loaded (as found: a path, or the bare soname for the dynamic linker's search).
    pub fn path(&self) -> &Path {
        &self.api.path
    }

    /// OIDN's version, `major * 10000 + minor * 100 + patch` (20501 for 2.5.1).
    pub fn version(&self) -> i32 {
        self.api.version
    }
}

/// Candidates for rules 3-6 of [`Library::find`], in order.
fn search_candidates() -> Vec<(&'static str, PathBuf)> {
    let mut out = Vec::new();
    if let Some(dir) = std::env::var_os("OIDN_DIR").filter(|v| !v.is_empty()) {
        out.push(("OIDN_DIR", PathBuf::from(dir).join("lib").join(LIB_NAME)));
    }
    let wheel_lib = Path::new(".oidn").join("pyoidn").join("oidn").join("lib").join(LIB_NAME);
    if let Ok(cwd) = std::env::current_dir() {
        out.push(("./.oidn", cwd.join(&wheel_lib)));
    }
    if let Ok(exe) = std::env::current_exe() {
        for dir in exe.ancestors().skip(1) {
            out.push(("executable's ancestors' .oidn", dir.join(&wheel_lib)));
        }
    }
    let mut prefixes = Vec::new();
    if let Some(venv) = std::env::var_os("VIRTUAL_ENV").filter(|v| !v.is_empty()) {
        prefixes.push(("VIRTUAL_ENV", PathBuf::from(venv).join("lib")));
    }
    if let Some(home) = std::env::var_os("HOME").filter(|v| !v.is_empty()) {
        prefixes.push(("~/.local", PathBuf::from(home).join(".local").join("lib")));
    }
    for (rule, lib) in prefixes {
        let mut pythons: Vec<PathBuf> = std::fs::read_dir(&lib)
            .map(|rd| {
                rd.flatten()
                    .map(|e| e.path())
                    .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("python3")))
                    .collect()
            })
            .unwrap_or_default();
        pythons.sort();
        if pythons.is_empty() {
            out.push((rule, lib.join("python3*").join("site-packages/pyoidn/oidn/lib").join(LIB_NAME)));
        }
        for py in pythons {
            out.push((rule, py.join("site-packages").join("pyoidn").join("oidn").join("lib").join(LIB_NAME)));
        }
    }
    out.push(("dynamic linker's search path", PathBuf::from(LIB_NAME)));
    out
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// Why a device or filter call failed.
#[derive(Clone, Debug, PartialEq)]
pub enum DenoiseError {
    /// Refused before any FFI call: bad sizes, a missing or mis-sized plane.
    InvalidInput(String),
    /// The device reports an OIDN older than [`MIN_VERSION`] (a library the probe in
    /// [`Library::find`] accepted should never do this).
    UnsupportedVersion(i32),
    /// OIDN reported an error at `stage` (e.g. `"beauty filter commit"`).
    Oidn {
        /// What was being done.
        stage: &'static str,
        /// OIDN's `OIDNError` code.
        code: i32,
        /// Its name: `INVALID_ARGUMENT`, `OUT_OF_MEMORY`, `UNSUPPORTED_HARDWARE`, ...
        name: &'static str,
        /// OIDN's message.
        message: String,
    },
}

impl fmt::Display for DenoiseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DenoiseError::InvalidInput(m) => write!(f, "invalid denoiser input: {m}"),
            DenoiseError::UnsupportedVersion(v) => {
                write!(f, "Open Image Denoise version {v} is older than {MIN_VERSION} (2.0.0)")
            }
            DenoiseError::Oidn { stage, code, name, message } => {
                write!(f, "Open Image Denoise {stage} failed: {name} ({code}): {message}")
            }
        }
    }
}

impl std::error::Error for DenoiseError {}

/// Checks that `plane` is a `width x height` RGB plane; returns its length.
fn check_plane(what: &str, plane: &[f32], width: usize, height: usize) -> Result<usize, DenoiseError> {
    let want = plane_len(width, height)?;
    if plane.len() != want {
        return Err(DenoiseError::InvalidInput(format!(
            "{what} has {} floats, a {width}x{height} RGB plane needs {want} (width * height * 3)",
            plane.len()
        )));
    }
    Ok(want)
}

/// `width * height * 3`, refusing zero sizes and any size whose byte count overflows.
fn plane_len(width: usize, height: usize) -> Result<usize, DenoiseError> {
    if width == 0 || height == 0 {
        return Err(DenoiseError::InvalidInput(format!("image size {width}x{height}: width and height must be > 0")));
    }
    width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(3))
        .filter(|n| n.checked_mul(4).is_some_and(|b| b <= isize::MAX as usize))
        .ok_or_else(|| DenoiseError::InvalidInput(format!("image size {width}x{height} overflows")))
}

// ---------------------------------------------------------------------------------------------
// Device
// ---------------------------------------------------------------------------------------------

/// CPU device settings. The default: OIDN picks the thread count, no pinning.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeviceOptions {
    /// OIDN's `numThreads`: 0 (the default) lets OIDN pick (all cores). Results do not depend on it.
    pub num_threads: u32,
    /// OIDN's `setAffinity`: pin OIDN's threads to cores. Off by default, since throng runs rayon
    /// pools in the same process and pinned TBB workers would fight them.
    pub set_affinity: bool,
}

/// An OIDNDevice, released on drop. `'a` is the [`Api`]'s: the probe in [`Api::open`] uses one
/// before the Api is cached; every [`Device`] holds a `'static` one.
struct RawDeviceHandle<'a> {
    api: &'a Api,
    raw: RawDevice,
    version: i32,
    num_threads: i32,
}

impl<'a> RawDeviceHandle<'a> {
    fn new(api: &'a Api, opts: &DeviceOptions) -> Result<RawDeviceHandle<'a>, DenoiseError> {
        let threads = i32::try_from(opts.num_threads)
            .map_err(|_| DenoiseError::InvalidInput(format!("num_threads {} is too large", opts.num_threads)))?;
        // SAFETY: plain constructor; a null result is handled below.
        let raw = unsafe { (api.new_device)(OIDN_DEVICE_TYPE_CPU) };
        if raw.is_null() {
            api.check(std::ptr::null_mut(), "CPU device creation")?;
            return Err(DenoiseError::Oidn {
                stage: "CPU device creation",
                code: 1,
                name: "UNKNOWN",
                message: "oidnNewDevice returned NULL".into(),
            });
        }
        // Owned from here: an early return releases it.
        let mut dev = RawDeviceHandle { api, raw, version: 0, num_threads: 0 };
        // SAFETY: `raw` is a live device; the names are NUL-terminated literals.
        unsafe {
            (api.set_device_int)(raw, c"numThreads".as_ptr(), threads);
            (api.set_device_bool)(raw, c"setAffinity".as_ptr(), opts.set_affinity);
        }
        api.check(raw, "device parameters")?;
        // SAFETY: `raw` is a live device.
        unsafe { (api.commit_device)(raw) };
        api.check(raw, "device commit")?;
        // SAFETY: `raw` is a live, committed device; the names are NUL-terminated literals.
        (dev.version, dev.num_threads) = unsafe {
            ((api.get_device_int)(raw, c"version".as_ptr()), (api.get_device_int)(raw, c"numThreads".as_ptr()))
        };
        api.check(raw, "device query")?;
        Ok(dev)
    }
}

impl Drop for RawDeviceHandle<'_> {
    fn drop(&mut self) {
        // SAFETY: `raw` is live and this is its only owner; filters hold their own reference.
        unsafe { (self.api.release_device)(self.raw) };
    }
}

// SAFETY: OIDN's API is thread-safe ("All API calls are thread-safe, operations that use the same
// device will be serialized"), and errors are recorded per device *and thread*, so a check after a
// call on one thread sees that call's error.
unsafe impl Send for RawDeviceHandle<'_> {}
// SAFETY: as for Send; the handle exposes no interior state besides the OIDN object.
unsafe impl Sync for RawDeviceHandle<'_> {}

/// An OIDN CPU device, committed. Cheap to clone (shared); filters made from it keep it alive.
#[derive(Clone)]
pub struct Device {
    inner: Arc<RawDeviceHandle<'static>>,
}

impl fmt::Debug for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Device").field("version", &self.version()).field("num_threads", &self.num_threads()).finish()
    }
}

impl Device {
    /// Creates and commits a CPU device; checks OIDN's version (>= [`MIN_VERSION`]) again.
    pub fn new(library: Library, options: DeviceOptions) -> Result<Device, DenoiseError> {
        let inner = RawDeviceHandle::new(library.api, &options)?;
        if inner.version < MIN_VERSION {
            return Err(DenoiseError::UnsupportedVersion(inner.version));
        }
        Ok(Device { inner: Arc::new(inner) })
    }

    /// OIDN's version, `major * 10000 + minor * 100 + patch`.
    pub fn version(&self) -> i32 {
        self.inner.version
    }

    /// The thread count OIDN committed (the number asked for, or what OIDN chose for 0).
    pub fn num_threads(&self) -> u32 {
        self.inner.num_threads.max(0) as u32
    }

    /// Denoises a noisy albedo guide (values in [0, 1]) into a clean one, for `clean_aux`.
    pub fn prefilter_albedo(
        &self,
        width: usize,
        height: usize,
        albedo: &[f32],
        quality: Quality,
    ) -> Result<Vec<f32>, DenoiseError> {
        self.prefilter(c"albedo", "albedo", width, height, albedo, quality)
    }

    /// Denoises a noisy normal guide (values in [-1, 1], any length) into a clean one, for `clean_aux`.
    pub fn prefilter_normal(
        &self,
        width: usize,
        height: usize,
        normal: &[f32],
        quality: Quality,
    ) -> Result<Vec<f32>, DenoiseError> {
        self.prefilter(c"normal", "normal", width, height, normal, quality)
    }

    fn prefilter(
        &self,
        image: &'static CStr,
        what: &'static str,
        width: usize,
        height: usize,
        plane: &[f32],
        quality: Quality,
    ) -> Result<Vec<f32>, DenoiseError> {
        check_plane(what, plane, width, height)?;
        let mut f = Filter::new(self, width, height, what)?;
        f.bind(image, plane.into())?;
        f.bind(c"output", vec![0.0; plane.len()].into_boxed_slice())?;
        f.set_int(c"quality", quality.raw())?;
        f.commit()?;
        f.execute()?;
        Ok(f.take(c"output").into_vec())
    }

    /// Denoises one beauty image. `albedo` and `normal` are the guides as handed to OIDN: clean
    /// (from [`Device::prefilter_albedo`] / [`Device::prefilter_normal`]) when `options.clean_aux`,
    /// raw otherwise. A normal guide needs an albedo guide too. For several images with the same
    /// guides, use a [`Denoiser`].
    pub fn denoise(
        &self,
        width: usize,
        height: usize,
        color: &[f32],
        albedo: Option<&[f32]>,
        normal: Option<&[f32]>,
        options: Options,
    ) -> Result<Vec<f32>, DenoiseError> {
        Denoiser::new(self, width, height, albedo, normal, options)?.denoise(color)
    }
}

// ---------------------------------------------------------------------------------------------
// Filters
// ---------------------------------------------------------------------------------------------

/// The RT filter's quality setting (OIDN_QUALITY_*).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Quality {
    /// OIDN_QUALITY_HIGH: final frames. The default.
    #[default]
    High,
    /// OIDN_QUALITY_BALANCED: interactive or preview renders.
    Balanced,
    /// OIDN_QUALITY_FAST: real-time previews.
    Fast,
}

impl Quality {
    fn raw(self) -> i32 {
        match self {
            Quality::High => 6,
            Quality::Balanced => 5,
            Quality::Fast => 4,
        }
    }
}

/// Beauty filter settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// The colour is HDR (values in [0, inf)), as a path tracer's beauty is. Default true.
    pub hdr: bool,
    /// The RT filter's quality. Default [`Quality::High`].
    pub quality: Quality,
    /// The guides are noise-free (prefiltered): OIDN's `cleanAux`. Default true.
    pub clean_aux: bool,
    /// OIDN's `inputScale` (None: OIDN's automatic exposure for HDR, 1 for LDR).
    pub input_scale: Option<f32>,
    /// OIDN's `maxMemoryMB` (None: OIDN's device-dependent limit). Can change the tiling, so the result.
    pub max_memory_mb: Option<u32>,
}

impl Default for Options {
    fn default() -> Self {
        Options { hdr: true, quality: Quality::High, clean_aux: true, input_scale: None, max_memory_mb: None }
    }
}

/// An OIDNFilter with the heap buffers bound to it as shared images, released on drop.
///
/// Invariant: every image OIDN holds a pointer to is a `Box<[f32]>` in `images`, neither moved
/// (a box's heap block stays put when the box moves) nor dropped before the filter is released.
struct Filter {
    device: Device,
    raw: RawFilter,
    width: usize,
    height: usize,
    what: &'static str,
    images: Vec<(&'static CStr, Box<[f32]>)>,
}

// SAFETY: see RawDeviceHandle's Send; the buffers are owned and only touched through &mut self.
unsafe impl Send for Filter {}

impl Filter {
    fn new(device: &Device, width: usize, height: usize, what: &'static str) -> Result<Filter, DenoiseError> {
        plane_len(width, height)?;
        let api = device.inner.api;
        // SAFETY: the device is live and committed; "RT" is a NUL-terminated literal.
        let raw = unsafe { (api.new_filter)(device.inner.raw, c"RT".as_ptr()) };
        api.check(device.inner.raw, "filter creation")?;
        if raw.is_null() {
            return Err(DenoiseError::Oidn {
                stage: "filter creation",
                code: 1,
                name: "UNKNOWN",
                message: "oidnNewFilter returned NULL".into(),
            });
        }
        Ok(Filter { device: device.clone(), raw, width, height, what, images: Vec::new() })
    }

    /// Names a stage for errors by the filter's role.
    fn stage(&self, beauty: &'static str, prefilter: &'static str) -> &'static str {
        if self.what == "beauty" {
            beauty
        } else {
            prefilter
        }
    }

    fn check(&self, stage: &'static str) -> Result<(), DenoiseError> {
        self.device.inner.api.check(self.device.inner.raw, stage)
    }

    /// Binds `buf` (a `width x height` plane, checked by the caller) as image `name`, replacing and
    /// freeing any buffer bound under that name before.
    fn bind(&mut self, name: &'static CStr, buf: Box<[f32]>) -> Result<(), DenoiseError> {
        assert_eq!(buf.len(), self.width * self.height * 3, "plane length checked by the caller");
        let mut buf = buf;
        let ptr = buf.as_mut_ptr().cast::<c_void>();
        // SAFETY: the filter is live; `ptr` addresses width*height*3 f32s (asserted above) laid out as
        // FLOAT3 rows with no padding (strides 0 = packed), and stays valid until the filter is
        // released or the name is re-bound: the box is kept in `images` (see the invariant).
        unsafe {
            (self.device.inner.api.set_shared_filter_image)(
                self.raw,
                name.as_ptr(),
                ptr,
                OIDN_FORMAT_FLOAT3,
                self.width,
                self.height,
                0,
                0,
                0,
            )
        };
        self.check(self.stage("beauty filter image binding", "prefilter image binding"))?;
        // Replace only after OIDN holds the new pointer, so the old one never dangles inside OIDN.
        match self.images.iter_mut().find(|(n, _)| *n == name) {
            Some(slot) => slot.1 = buf,
            None => self.images.push((name, buf)),
        }
        Ok(())
    }

    fn image_mut(&mut self, name: &CStr) -> &mut [f32] {
        self.images.iter_mut().find(|(n, _)| *n == name).map(|(_, b)| &mut b[..]).expect("image bound")
    }

    fn image(&self, name: &CStr) -> &[f32] {
        self.images.iter().find(|(n, _)| *n == name).map(|(_, b)| &b[..]).expect("image bound")
    }

    /// Moves a bound buffer out, releasing the filter first (the filter is consumed).
    fn take(mut self, name: &CStr) -> Box<[f32]> {
        let i = self.images.iter().position(|(n, _)| *n == name).expect("image bound");
        let buf = std::mem::take(&mut self.images[i].1);
        drop(self); // releases the filter; `buf` was never freed, so OIDN's pointer never dangled while live
        buf
    }

    fn set_bool(&mut self, name: &'static CStr, value: bool) -> Result<(), DenoiseError> {
        // SAFETY: live filter, NUL-terminated name.
        unsafe { (self.device.inner.api.set_filter_bool)(self.raw, name.as_ptr(), value) };
        self.check("filter parameter")
    }

    fn set_int(&mut self, name: &'static CStr, value: i32) -> Result<(), DenoiseError> {
        // SAFETY: live filter, NUL-terminated name.
        unsafe { (self.device.inner.api.set_filter_int)(self.raw, name.as_ptr(), value) };
        self.check("filter parameter")
    }

    fn set_float(&mut self, name: &'static CStr, value: f32) -> Result<(), DenoiseError> {
        // SAFETY: live filter, NUL-terminated name.
        unsafe { (self.device.inner.api.set_filter_float)(self.raw, name.as_ptr(), value) };
        self.check("filter parameter")
    }

    fn commit(&mut self) -> Result<(), DenoiseError> {
        // SAFETY: live filter; its images are bound to live buffers (the invariant).
        unsafe { (self.device.inner.api.commit_filter)(self.raw) };
        self.check(self.stage("beauty filter commit", "prefilter commit"))
    }

    fn execute(&mut self) -> Result<(), DenoiseError> {
        // SAFETY: live, committed filter; it reads its input buffers and writes its output buffer,
        // all owned by `self` and borrowed mutably here, so nothing else reads or writes them.
        unsafe { (self.device.inner.api.execute_filter)(self.raw) };
        self.check(self.stage("beauty filter execute", "prefilter execute"))
    }
}

impl Drop for Filter {
    fn drop(&mut self) {
        // SAFETY: `raw` is live and owned only by this wrapper. After this call OIDN holds no
        // pointer into `images`, which drop after it.
        unsafe { (self.device.inner.api.release_filter)(self.raw) };
    }
}

/// A reusable beauty denoiser for one image size and one set of guides: it keeps the guides and
/// a committed RT filter whose colour and output images are its own buffers, so each pass costs
/// two copies of the image and an execute: no filter creation, no commit (see
/// [`Denoiser::denoise_into`]).
pub struct Denoiser {
    filter: Filter,
    options: Options,
}

impl fmt::Debug for Denoiser {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Denoiser")
            .field("width", &self.filter.width)
            .field("height", &self.filter.height)
            .field("options", &self.options)
            .finish()
    }
}

impl Denoiser {
    /// A denoiser with the given guides as handed to OIDN: clean when `options.clean_aux` (see
    /// [`Denoiser::prefiltered`] to get them cleaned here), raw otherwise. A normal guide needs an
    /// albedo guide too (OIDN's rule).
    pub fn new(
        device: &Device,
        width: usize,
        height: usize,
        albedo: Option<&[f32]>,
        normal: Option<&[f32]>,
        options: Options,
    ) -> Result<Denoiser, DenoiseError> {
        let len = plane_len(width, height)?;
        if let Some(a) = albedo {
            check_plane("albedo guide", a, width, height)?;
        }
        if let Some(n) = normal {
            check_plane("normal guide", n, width, height)?;
            if albedo.is_none() {
                return Err(DenoiseError::InvalidInput("a normal guide needs an albedo guide too".into()));
            }
        }
        let mut filter = Filter::new(device, width, height, "beauty")?;
        filter.bind(c"color", vec![0.0; len].into_boxed_slice())?;
        filter.bind(c"output", vec![0.0; len].into_boxed_slice())?;
        if let Some(a) = albedo {
            filter.bind(c"albedo", a.into())?;
        }
        if let Some(n) = normal {
            filter.bind(c"normal", n.into())?;
        }
        filter.set_bool(c"hdr", options.hdr)?;
        filter.set_bool(c"cleanAux", options.clean_aux)?;
        filter.set_int(c"quality", options.quality.raw())?;
        if let Some(s) = options.input_scale {
            filter.set_float(c"inputScale", s)?;
        }
        if let Some(mb) = options.max_memory_mb {
            let mb = i32::try_from(mb)
                .map_err(|_| DenoiseError::InvalidInput(format!("max_memory_mb {mb} is too large")))?;
            filter.set_int(c"maxMemoryMB", mb)?;
        }
        filter.commit()?;
        Ok(Denoiser { filter, options })
    }

    /// Prefilters raw guides (with `options.quality`) and builds a denoiser on the clean ones,
    /// with `clean_aux` set.
    pub fn prefiltered(
        device: &Device,
        width: usize,
        height: usize,
        raw_albedo: Option<&[f32]>,
        raw_normal: Option<&[f32]>,
        options: Options,
    ) -> Result<Denoiser, DenoiseError> {
        if raw_normal.is_some() && raw_albedo.is_none() {
            return Err(DenoiseError::InvalidInput("a normal guide needs an albedo guide too".into()));
        }
        let albedo = raw_albedo.map(|a| device.prefilter_albedo(width, height, a, options.quality)).transpose()?;
        let normal = raw_normal.map(|n| device.prefilter_normal(width, height, n, options.quality)).transpose()?;
        Denoiser::new(
            device,
            width,
            height,
            albedo.as_deref(),
            normal.as_deref(),
            Options { clean_aux: true, ..options },
        )
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.filter.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.filter.height
    }

    /// The settings the beauty filter was committed with.
    pub fn options(&self) -> Options {
        self.options
    }

    /// The albedo guide handed to OIDN (clean if `clean_aux`).
    pub fn albedo(&self) -> Option<&[f32]> {
        self.filter.images.iter().find(|(n, _)| *n == c"albedo").map(|(_, b)| &b[..])
    }

    /// The normal guide handed to OIDN (clean if `clean_aux`).
    pub fn normal(&self) -> Option<&[f32]> {
        self.filter.images.iter().find(|(n, _)| *n == c"normal").map(|(_, b)| &b[..])
    }

    /// Denoises one pass of the image.
    pub fn denoise(&mut self, color: &[f32]) -> Result<Vec<f32>, DenoiseError> {
        let mut out = vec![0.0; color.len()];
        self.denoise_into(color, &mut out)?;
        Ok(out)
    }

    /// Denoises one pass of the image into `out` (same length as `color`). Copies `color` into the
    /// filter's bound colour buffer, executes, and copies the bound output buffer to `out`.
    pub fn denoise_into(&mut self, color: &[f32], out: &mut [f32]) -> Result<(), DenoiseError> {
        let (w, h) = (self.filter.width, self.filter.height);
        check_plane("color", color, w, h)?;
        check_plane("output", out, w, h)?;
        self.filter.image_mut(c"color").copy_from_slice(color);
        self.filter.execute()?;
        out.copy_from_slice(self.filter.image(c"output"));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_sizes_are_checked() {
        assert_eq!(plane_len(4, 2), Ok(24));
        assert!(plane_len(0, 2).is_err());
        assert!(plane_len(2, 0).is_err());
        assert!(plane_len(usize::MAX / 2, 3).is_err());
        assert!(check_plane("color", &[0.0; 23], 4, 2).is_err());
        assert!(check_plane("color", &[0.0; 24], 4, 2).is_ok());
    }

    #[test]
    fn find_error_names_the_install_routes() {
        let e = FindError {
            searched: vec![Searched { rule: "THRONG_OIDN", path: "/nowhere".into(), outcome: "not found".into() }],
        };
        let text = e.to_string();
        assert!(text.contains("THRONG_OIDN") && text.contains(PIP_INSTALL) && text.contains("/nowhere"), "{text}");
    }
}
