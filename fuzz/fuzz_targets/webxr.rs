#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|d: &[u8]| fuzz_targets::webxr(d));
