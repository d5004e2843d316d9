//! Compiles `deog/v1/*.proto` with protox (no system protoc) and writes the
//! descriptor set next to the generated code for the reflection service.

use std::{error::Error, path::PathBuf};

use prost::Message;

const PROTO_ROOT: &str = "deog/v1";
const FILES: [&str; 3] = [
    "deog/v1/common.proto",
    "deog/v1/map.proto",
    "deog/v1/robot.proto",
];

fn main() -> Result<(), Box<dyn Error>> {
    println!("cargo:rerun-if-changed={PROTO_ROOT}");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    let descriptors = protox::compile(FILES, ["."])?;
    std::fs::write(
        out_dir.join("deog_descriptor.bin"),
        descriptors.encode_to_vec(),
    )?;
    tonic_prost_build::configure()
        .build_client(true)
        .build_server(true)
        .compile_fds(descriptors)?;
    Ok(())
}
