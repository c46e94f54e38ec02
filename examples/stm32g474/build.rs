//! Link arguments for the firmware binaries: cortex-m-rt's linker script (with the
//! `memory.x` embassy-stm32 generates for the STM32G474RE) and defmt's.

fn main() {
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
