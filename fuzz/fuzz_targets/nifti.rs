//! The Nifti label image reader must return Ok or a typed error for any
//! bytes, never panic, and never take more memory than its limit.
#![no_main]
use hexmesh::image::{ImageFormat, ImageLimits, load_image_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = ImageLimits { max_bytes: 64 << 20 };
    if let Ok(image) = load_image_bytes(data, ImageFormat::Nifti, "fuzz", &limits) {
        assert_eq!(image.labels.len(), image.dims.iter().product::<usize>());
        assert!(image.affine.iter().flatten().all(|v| v.is_finite()));
    }
});
