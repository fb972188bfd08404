# Sourced by the scripts that build: one compiler setting for every build of the dev profile, so the demo,
# the tests and the lints share their artifacts. Clippy runs as the compiler wrapper of the workspace's own
# crates (what `cargo clippy` does, but within the real build instead of a separate check build), with
# warnings denied; dependencies are compiled by rustc once.
export RUSTC_WORKSPACE_WRAPPER="${RUSTC_WORKSPACE_WRAPPER:-$(command -v clippy-driver)}"
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
export CARGO_BUILD_JOBS="${CARGO_BUILD_JOBS:-2}"
