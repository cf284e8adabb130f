//! The error for a missing library names its way out. Its own test binary: Library::find
//! caches the first load for the process, so this must run where nothing has loaded OIDN.

use std::path::Path;

use throng_oidn::{Library, PIP_INSTALL};

#[test]
fn missing_library_error_names_throng_oidn_and_pip() {
    let err = Library::find(Some(Path::new("/nonexistent/oidn/lib"))).unwrap_err();
    let text = err.to_string();
    println!("{text}");
    assert_eq!(err.searched.len(), 1, "an explicit path is the only candidate: {text}");
    assert!(text.contains("/nonexistent/oidn/lib"), "{text}");
    assert!(text.contains("THRONG_OIDN"), "{text}");
    assert!(text.contains(PIP_INSTALL), "{text}");
    assert!(text.contains("pip install --no-deps --target .oidn pyoidn==2.5.1.0"), "{text}");
}
