//! Segmented images: label volumes (one integer label per voxel, as CT and
//! MRI segmentations from 3D Slicer, ITK-SNAP or nibabel are stored) read
//! from NIfTI-1, NIfTI-2 and NRRD files, resampled onto a cubic lattice, and
//! the labels' boundary extracted as a surface for rendering.
//!
//! - [`LabelImage`]: the voxels' labels (`i32`, x fastest) and the map from
//!   voxel indices to the file's world coordinates ([`LabelImage::affine`]:
//!   NIfTI's sform, else its qform, else its pixel sizes; NRRD's space
//!   directions and origin, else its spacings). The voxel `(i, j, k)` is
//!   centred at `affine * (i, j, k, 1)` and spans half a voxel either side in
//!   index space.
//! - [`load_image`] reads a file by its extension (`.nii`, `.nii.gz`, `.hdr`
//!   with its `.img`, `.nrrd`, `.nhdr` with its data file);
//!   [`load_image_bytes`] reads a whole file held in memory (attached data
//!   only). Both estimate the memory the voxels need from the header and
//!   refuse past [`ImageLimits::max_bytes`] before reading them; the labels
//!   grow only as the data actually arrives, so a header that claims more
//!   voxels than a compressed stream holds costs no more than the stream.
//! - [`resample`](mod@resample): the voxels carrying chosen labels to a
//!   lattice of cubic cells (any voxel size and orientation), each cell
//!   kept when the chosen labels cover at least a threshold of it and given
//!   the label covering most of it.
//! - [`surface`]: the boundary of the chosen labels as a closed triangle
//!   surface (surface nets over the voxel mask), in world coordinates.
//!
//! We read both formats ourselves (see ARCHITECTURE.md): the `nifti` crate
//! reads NIfTI-1 only and allocates what the header declares before it
//! reads, and no maintained crate reads NRRD.
//!
//! ```
//! use hexmesh::image::{ImageFormat, ImageLimits, load_image_bytes};
//!
//! // A 2 x 1 x 1 NRRD label image with attached raw data, 0.5 mm voxels.
//! let mut bytes = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 1 1\n\
//!     space: left-posterior-superior\nspace directions: (0.5,0,0) (0,0.5,0) (0,0,0.5)\n\
//!     space origin: (10,20,30)\nencoding: raw\n\n".to_vec();
//! bytes.extend([0u8, 7]);
//! let image = load_image_bytes(&bytes, ImageFormat::Nrrd, "tiny.nrrd", &ImageLimits::default()).unwrap();
//! assert_eq!(image.dims, [2, 1, 1]);
//! assert_eq!(image.labels, vec![0, 7]);
//! assert_eq!(image.voxel_to_world([1.0, 0.0, 0.0]), [10.5, 20.0, 30.0]);
//! ```

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use thiserror::Error;

mod nifti;
mod nrrd;
pub mod plane;
pub mod resample;
pub mod surface;

pub use resample::{ImageLattice, ImageVoxelizeOptions, resample};

/// The image file formats read here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// NIfTI-1 or NIfTI-2, one file (`.nii`), gzip-compressed or not
    /// (detected from the bytes), or a header (`.hdr`) beside its `.img`.
    Nifti,
    /// NRRD (`.nrrd` with attached data, `.nhdr` with a data file).
    Nrrd,
}

impl ImageFormat {
    /// The format a file name's extension says (`.nii`, `.nii.gz`, `.hdr`,
    /// `.hdr.gz`, `.nrrd`, `.nhdr`; any case), or `None`.
    pub fn from_path(path: &Path) -> Option<ImageFormat> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        let name = name.strip_suffix(".gz").unwrap_or(&name);
        if name.ends_with(".nii") || name.ends_with(".hdr") {
            Some(ImageFormat::Nifti)
        } else if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
            Some(ImageFormat::Nrrd)
        } else {
            None
        }
    }
}

/// The anatomical frame of a file's world coordinates.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Space {
    /// x towards the patient's right, y anterior, z superior (NIfTI's
    /// frame; NRRD `right-anterior-superior`).
    Ras,
    /// x to the left, y posterior, z superior (DICOM's and ITK's frame;
    /// NRRD `left-posterior-superior`).
    Lps,
    /// Another frame the file names (NRRD `scanner-xyz`, `3D-right-handed`,
    /// ...), or none: coordinates are used as they are.
    Other(String),
}

/// A label volume and where its voxels are.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelImage {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// One label per voxel, `i + dims[0] * (j + dims[1] * k)`.
    pub labels: Vec<i32>,
    /// Rows of the map from voxel indices `(i, j, k, 1)` to world
    /// coordinates, in the file's units.
    pub affine: [[f64; 4]; 3],
    /// Metres per unit of the world coordinates, when the file says
    /// (NIfTI `xyzt_units`, NRRD `space units`).
    pub unit_metres: Option<f64>,
    /// The frame of the world coordinates.
    pub space: Space,
    /// The format read.
    pub format: ImageFormat,
}

/// Unit assumed for medical images whose file does not name one: the
/// millimetre, as scanners and segmentation tools write them.
pub const DEFAULT_UNIT_METRES: f64 = 1e-3;

/// What reading an image may cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageLimits {
    /// Bytes the labels may take (4 per voxel) with the largest data chunk
    /// in flight; a header declaring more is refused before its data is read.
    pub max_bytes: u64,
}

impl Default for ImageLimits {
    fn default() -> Self {
        Self { max_bytes: 8 << 30 }
    }
}

/// Bytes [`LabelImage`] holds per voxel.
pub const LABEL_BYTES_PER_VOXEL: u64 = 4;

/// Why an image could not be read.
#[derive(Debug, Error)]
pub enum ImageError {
    /// The file (or its data file) could not be opened or read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The extension names no image format read here.
    #[error(
        "{path}: not a label image this tool reads (use .nii, .nii.gz, .hdr/.img, .nrrd or .nhdr)"
    )]
    UnknownFormat {
        /// The file.
        path: String,
    },
    /// The file ends before what its header declares.
    #[error("{path}: the file ends after {got} bytes of {what}, but the header declares {needed}")]
    Truncated {
        /// The file.
        path: String,
        /// Which part.
        what: &'static str,
        /// Bytes the header declares.
        needed: u64,
        /// Bytes there are.
        got: u64,
    },
    /// A header field has an unusable value.
    #[error("{path}: {field} = {value}: {why}")]
    BadField {
        /// The file.
        path: String,
        /// The field, as the format names it.
        field: String,
        /// Its value as read.
        value: String,
        /// What is wrong, and what a label image needs.
        why: String,
    },
    /// A header line could not be read (NRRD).
    #[error("{path}:{line}: {message}")]
    BadLine {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The voxels would need more memory than allowed.
    #[error(
        "{path}: {dims:?} voxels would need about {needed} bytes, more than the limit of {limit}: \
         crop the image to the structures to simulate"
    )]
    TooLarge {
        /// The file.
        path: String,
        /// Voxels along each axis.
        dims: [u64; 3],
        /// Estimated bytes.
        needed: u64,
        /// The limit.
        limit: u64,
    },
    /// Compressed data could not be decompressed.
    #[error("{path}: cannot decompress the voxel data: {message}")]
    Decompress {
        /// The file.
        path: String,
        /// The decoder's message.
        message: String,
    },
    /// A floating-point voxel holds a value that is not an integer label.
    #[error(
        "{path}: voxel {index:?} holds {value}, which is not a label (labels are whole numbers \
         between -2^31 and 2^31 - 1; is this an intensity image?)"
    )]
    NotALabel {
        /// The file.
        path: String,
        /// The voxel.
        index: [usize; 3],
        /// Its value.
        value: f64,
    },
}

impl LabelImage {
    /// A label image from its parts, checked: positive dimensions whose
    /// product is the number of labels, a finite affine whose linear part
    /// is invertible.
    pub fn new(
        dims: [usize; 3],
        labels: Vec<i32>,
        affine: [[f64; 4]; 3],
        name: &str,
    ) -> Result<Self, ImageError> {
        Self::from_reader(
            dims,
            labels,
            affine,
            None,
            Space::Other(String::new()),
            ImageFormat::Nifti,
            name,
        )
    }

    /// What a reader assembles: checked as [`LabelImage::new`] is.
    pub(crate) fn from_reader(
        dims: [usize; 3],
        labels: Vec<i32>,
        affine: [[f64; 4]; 3],
        unit_metres: Option<f64>,
        space: Space,
        format: ImageFormat,
        name: &str,
    ) -> Result<Self, ImageError> {
        let image = LabelImage {
            dims,
            labels,
            affine,
            unit_metres,
            space,
            format,
        };
        image.check(name)?;
        Ok(image)
    }

    fn check(&self, name: &str) -> Result<(), ImageError> {
        let bad = |field: &str, value: String, why: &str| ImageError::BadField {
            path: name.to_owned(),
            field: field.to_owned(),
            value,
            why: why.to_owned(),
        };
        let voxels = self
            .dims
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .filter(|&n| n > 0);
        if voxels != Some(self.labels.len()) {
            return Err(bad(
                "dimensions",
                format!("{:?}", self.dims),
                &format!(
                    "do not match the {} labels given (every dimension must be at least 1)",
                    self.labels.len()
                ),
            ));
        }
        if self.affine.iter().flatten().any(|v| !v.is_finite()) {
            return Err(bad(
                "voxel-to-world transform",
                format!("{:?}", self.affine),
                "has a non-finite entry",
            ));
        }
        let det = self.linear_determinant();
        let scale = self
            .affine
            .iter()
            .flat_map(|r| r[..3].iter())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        // NaN compares false: a NaN determinant is refused too.
        if det.abs() <= 1e-12 * scale.powi(3) || det.is_nan() || scale == 0.0 {
            return Err(bad(
                "voxel-to-world transform",
                format!("{:?}", self.affine),
                "flattens the voxels (its linear part is singular): every axis needs a non-zero spacing",
            ));
        }
        Ok(())
    }

    /// Number of voxels.
    pub fn num_voxels(&self) -> usize {
        self.labels.len()
    }

    /// The label of voxel `(i, j, k)`.
    pub fn label(&self, ijk: [usize; 3]) -> i32 {
        self.labels[ijk[0] + self.dims[0] * (ijk[1] + self.dims[1] * ijk[2])]
    }

    /// World coordinates (file units) of a point given in voxel indices
    /// (voxel centres at whole numbers).
    pub fn voxel_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        let a = &self.affine;
        std::array::from_fn(|r| a[r][0] * ijk[0] + a[r][1] * ijk[1] + a[r][2] * ijk[2] + a[r][3])
    }

    /// Determinant of the affine's linear part: a voxel's signed volume in
    /// file units cubed.
    pub fn linear_determinant(&self) -> f64 {
        linear_det(&self.affine)
    }

    /// Voxel spacing along each index axis (file units).
    pub fn spacing(&self) -> [f64; 3] {
        std::array::from_fn(|c| {
            (0..3)
                .map(|r| self.affine[r][c] * self.affine[r][c])
                .sum::<f64>()
                .sqrt()
        })
    }

    /// How many voxels carry each label, in label order.
    pub fn label_counts(&self) -> BTreeMap<i32, usize> {
        let mut counts = BTreeMap::new();
        for &l in &self.labels {
            *counts.entry(l).or_insert(0) += 1;
        }
        counts
    }

    /// Metres per unit of the world coordinates: the file's unit, else
    /// [`DEFAULT_UNIT_METRES`].
    pub fn unit_metres_or_default(&self) -> f64 {
        self.unit_metres.unwrap_or(DEFAULT_UNIT_METRES)
    }

    /// The map from voxel indices to the simulation's coordinates (m): the
    /// file's world coordinates times `unit_metres`, then `placement`
    /// (whose own `units` multiply again: leave them at metres).
    pub fn to_metres(&self, unit_metres: f64, placement: &crate::Placement) -> [[f64; 4]; 3] {
        let (p, t) = placement.affine();
        std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                let v: f64 = (0..3).map(|m| p[r][m] * self.affine[m][c]).sum();
                unit_metres * v + if c == 3 { t[r] } else { 0.0 }
            })
        })
    }

    /// The same image with its world coordinates expressed in `target`
    /// (RAS and LPS differ by the sign of x and y); a frame of another
    /// kind, or the same, changes nothing.
    pub fn in_space(mut self, target: &Space) -> Self {
        let flip = matches!(
            (&self.space, target),
            (Space::Ras, Space::Lps) | (Space::Lps, Space::Ras)
        );
        if flip {
            for row in &mut self.affine[..2] {
                for v in row.iter_mut() {
                    *v = -*v;
                }
            }
            self.space = target.clone();
        }
        self
    }
}

/// Reads the label image at `path`, its format chosen by the extension
/// ([`ImageFormat::from_path`]).
pub fn load_image(path: &Path, limits: &ImageLimits) -> Result<LabelImage, ImageError> {
    let name = path.display().to_string();
    match ImageFormat::from_path(path) {
        Some(ImageFormat::Nifti) => nifti::read_file(path, &name, limits),
        Some(ImageFormat::Nrrd) => nrrd::read_file(path, &name, limits),
        None => Err(ImageError::UnknownFormat { path: name }),
    }
}

/// Reads a whole image file held in memory (`name` names it in errors).
/// NIfTI may be gzip-compressed; NRRD must carry its data (a detached
/// header names a file, which only [`load_image`] can open).
pub fn load_image_bytes(
    bytes: &[u8],
    format: ImageFormat,
    name: &str,
    limits: &ImageLimits,
) -> Result<LabelImage, ImageError> {
    match format {
        ImageFormat::Nifti => nifti::read_bytes(bytes, name, limits),
        ImageFormat::Nrrd => nrrd::read_bytes(bytes, name, limits),
    }
}

/// The voxel types label images are stored in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum VoxelType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl VoxelType {
    pub(crate) fn bytes(self) -> usize {
        match self {
            VoxelType::U8 | VoxelType::I8 => 1,
            VoxelType::U16 | VoxelType::I16 => 2,
            VoxelType::U32 | VoxelType::I32 | VoxelType::F32 => 4,
            VoxelType::U64 | VoxelType::I64 | VoxelType::F64 => 8,
        }
    }

    /// The value of one voxel's bytes.
    fn value(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty) => {{
                let raw: [u8; std::mem::size_of::<$t>()] = b.try_into().expect("voxel width");
                (if big_endian {
                    <$t>::from_be_bytes(raw)
                } else {
                    <$t>::from_le_bytes(raw)
                }) as f64
            }};
        }
        match self {
            VoxelType::U8 => b[0] as f64,
            VoxelType::I8 => b[0] as i8 as f64,
            VoxelType::U16 => num!(u16),
            VoxelType::I16 => num!(i16),
            VoxelType::U32 => num!(u32),
            VoxelType::I32 => num!(i32),
            VoxelType::U64 => num!(u64),
            VoxelType::I64 => num!(i64),
            VoxelType::F32 => num!(f32),
            VoxelType::F64 => num!(f64),
        }
    }
}

/// How the voxels are laid out in the data stream.
pub(crate) struct VoxelLayout {
    pub dims: [usize; 3],
    pub kind: VoxelType,
    pub big_endian: bool,
    /// `value * slope + intercept` is the label (NIfTI's scaling).
    pub slope: f64,
    pub intercept: f64,
}

impl VoxelLayout {
    /// The number of voxels, saturating: a header may declare dimensions
    /// whose product overflows, which the memory check then refuses.
    pub(crate) fn voxels(&self) -> u64 {
        self.dims
            .iter()
            .fold(1u64, |n, &d| n.saturating_mul(d as u64))
    }

    pub(crate) fn data_bytes(&self) -> u64 {
        self.voxels().saturating_mul(self.kind.bytes() as u64)
    }

    /// Refuses a layout whose labels would not fit in `limits`.
    pub(crate) fn check_memory(&self, name: &str, limits: &ImageLimits) -> Result<(), ImageError> {
        let needed = self
            .voxels()
            .saturating_mul(LABEL_BYTES_PER_VOXEL)
            .saturating_add(CHUNK_BYTES as u64);
        if needed > limits.max_bytes || usize::try_from(self.voxels()).is_err() {
            return Err(ImageError::TooLarge {
                path: name.to_owned(),
                dims: self.dims.map(|d| d as u64),
                needed,
                limit: limits.max_bytes,
            });
        }
        Ok(())
    }

    /// The labels of the voxel data `reader` streams, in chunks, growing
    /// only as data arrives.
    pub(crate) fn read_labels(
        &self,
        reader: &mut dyn Read,
        name: &str,
        compressed: bool,
    ) -> Result<Vec<i32>, ImageError> {
        let voxels = self.voxels() as usize;
        let width = self.kind.bytes();
        let mut labels = Vec::with_capacity(voxels.min(CHUNK_BYTES));
        let mut chunk = vec![0u8; (CHUNK_BYTES / width) * width];
        let mut carried = 0usize;
        let identity = self.slope == 1.0 && self.intercept == 0.0;
        while labels.len() < voxels {
            let want = ((voxels - labels.len()) * width).min(chunk.len());
            let got = match reader.read(&mut chunk[carried..want]) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) if compressed => {
                    return Err(ImageError::Decompress {
                        path: name.to_owned(),
                        message: e.to_string(),
                    });
                }
                Err(source) => {
                    return Err(ImageError::Io {
                        path: name.to_owned(),
                        source,
                    });
                }
            };
            if got == 0 {
                return Err(ImageError::Truncated {
                    path: name.to_owned(),
                    what: "voxel data",
                    needed: self.data_bytes(),
                    got: (labels.len() * width + carried) as u64,
                });
            }
            let filled = carried + got;
            let whole = filled / width * width;
            for b in chunk[..whole].chunks_exact(width) {
                let raw = self.kind.value(b, self.big_endian);
                let value = if identity {
                    raw
                } else {
                    raw * self.slope + self.intercept
                };
                labels.push(self.to_label(value, labels.len(), name)?);
            }
            chunk.copy_within(whole..filled, 0);
            carried = filled - whole;
        }
        Ok(labels)
    }

    fn to_label(&self, value: f64, at: usize, name: &str) -> Result<i32, ImageError> {
        if value.fract() == 0.0 && value >= i32::MIN as f64 && value <= i32::MAX as f64 {
            return Ok(value as i32);
        }
        let [nx, ny, _] = self.dims;
        Err(ImageError::NotALabel {
            path: name.to_owned(),
            index: [at % nx, (at / nx) % ny, at / (nx * ny)],
            value,
        })
    }
}

/// Determinant of an affine map's linear part.
pub(crate) fn linear_det(a: &[[f64; 4]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// Skips `n` bytes of a stream (header extensions, NRRD byte skips).
pub(crate) fn skip_bytes(
    reader: &mut dyn Read,
    n: u64,
    what: &'static str,
    name: &str,
) -> Result<(), ImageError> {
    let got = std::io::copy(&mut reader.take(n), &mut std::io::sink()).map_err(|e| {
        ImageError::Decompress {
            path: name.to_owned(),
            message: e.to_string(),
        }
    })?;
    if got < n {
        return Err(ImageError::Truncated {
            path: name.to_owned(),
            what,
            needed: n,
            got,
        });
    }
    Ok(())
}

/// Bytes of voxel data decoded at a time.
const CHUNK_BYTES: usize = 1 << 20;

/// Whether `bytes` start like a gzip stream.
pub(crate) fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1f, 0x8b])
}

fn io_error(name: &str) -> impl Fn(std::io::Error) -> ImageError + '_ {
    move |source| ImageError::Io {
        path: name.to_owned(),
        source,
    }
}
