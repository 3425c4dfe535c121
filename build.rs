//! Build facts the binary reports: `CAMLOOP_BUILD_EPOCH_S`, the build's time in Unix seconds
//! (the OPC UA server's BuildInfo.BuildDate). `SOURCE_DATE_EPOCH` fixes it for reproducible
//! builds; otherwise it is when this script ran. It reruns only when that variable or this
//! file changes, so an edit elsewhere does not rebuild the crate for a new date.

use std::time::{SystemTime, UNIX_EPOCH};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=SOURCE_DATE_EPOCH");
    let seconds = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(0))
        });
    println!("cargo:rustc-env=CAMLOOP_BUILD_EPOCH_S={seconds}");
}
