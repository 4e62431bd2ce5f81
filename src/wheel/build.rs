//! The extension module finds MuJoCo in the `mujoco==3.17.0` wheel it depends on, installed
//! beside it (`site-packages/mujoco/libmujoco.so.3.17.0`); Python itself is the process that
//! loads it, so no libpython is named (maturin builds it with PYO3_BUILD_EXTENSION_MODULE).

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-cdylib=-Wl,-rpath,$ORIGIN/../mujoco");
}
