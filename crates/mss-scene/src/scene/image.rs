//! `[image]`: a segmented label volume (NIfTI or NRRD) as the body, instead
//! of `[mesh]`: which labels form it, how much of a cell they must cover,
//! the unit and frame of the file's coordinates, and where it is placed.

use hexmesh::image::Space;
use hexmesh::placement::{Placement, Units};
use serde::Deserialize;

use super::key::KeyError;

/// `[image]`: a label image whose chosen labels form the body. The lattice
/// takes `[voxelize] cells` or `cell_size` (cubes, whatever the voxels'
/// shape); `[voxelize] rule` does not apply (the cells covered at least
/// `threshold` are kept).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSection {
    /// The label volume (`.nii`, `.nii.gz`, `.hdr`, `.nrrd`, `.nhdr`),
    /// relative to the scene file's folder.
    pub path: String,
    /// The labels that form the body (default: every non-zero label).
    #[serde(default)]
    pub labels: Option<Vec<i32>>,
    /// Fraction of a cell the chosen labels must cover for it to be kept
    /// (0 < t <= 1, default 0.5).
    #[serde(default = "default_threshold")]
    pub threshold: f64,
    /// Unit of the file's world coordinates: `"m"`, `"cm"` or `"mm"`
    /// (default: the unit the file names, else millimetres).
    #[serde(default)]
    pub units: Option<Units>,
    /// The frame the coordinates are taken in: `"file"` (default: as the
    /// file gives them), `"RAS"` or `"LPS"` (converted when the file names
    /// the other; RAS and LPS differ by the sign of x and y).
    #[serde(default)]
    pub space: ImageSpace,
    /// Rotation about the fixed x, then y, then z axis (degrees), after the
    /// file's own transform.
    #[serde(default)]
    pub rotate: [f64; 3],
    /// Translation applied last (m).
    #[serde(default)]
    pub translate: [f64; 3],
}

/// `[image] space`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
pub enum ImageSpace {
    /// The file's own coordinates.
    #[default]
    #[serde(rename = "file")]
    File,
    /// Right-anterior-superior (NIfTI's, 3D Slicer's display frame).
    #[serde(rename = "RAS")]
    Ras,
    /// Left-posterior-superior (DICOM's, ITK's).
    #[serde(rename = "LPS")]
    Lps,
}

impl ImageSpace {
    /// The frame to convert to, or `None` to keep the file's.
    pub fn target(self) -> Option<Space> {
        match self {
            ImageSpace::File => None,
            ImageSpace::Ras => Some(Space::Ras),
            ImageSpace::Lps => Some(Space::Lps),
        }
    }
}

fn default_threshold() -> f64 {
    0.5
}

impl ImageSection {
    /// Checks the keys: a path, a non-empty label list, a threshold in
    /// (0, 1], a placement that applies.
    pub fn check(&self) -> Result<(), KeyError> {
        if self.path.trim().is_empty() {
            return Err(KeyError::new(
                "path",
                "is empty; give a label image (.nii, .nii.gz, .nrrd, .nhdr; relative to the scene file)",
            ));
        }
        if let Some(labels) = &self.labels
            && labels.is_empty()
        {
            return Err(KeyError::new(
                "labels",
                "= []; name the labels that form the body, or leave the key out for every non-zero label",
            ));
        }
        if !(self.threshold > 0.0 && self.threshold <= 1.0) {
            return Err(KeyError::new(
                "threshold",
                format!(
                    "= {}; the fraction of a cell the labels must cover is in (0, 1]",
                    self.threshold
                ),
            ));
        }
        if let Err(e) = self.placement().validate() {
            let key = match e {
                hexmesh::PlacementError::NonFinite { what: "rotate", .. } => "rotate",
                _ => "translate",
            };
            return Err(KeyError::new(key, e.to_string()));
        }
        Ok(())
    }

    /// The placement after the file's transform and unit (`rotate`, then
    /// `translate`); its units are metres, the file's unit being applied
    /// before it.
    pub fn placement(&self) -> Placement {
        Placement {
            rotate_degrees: self.rotate,
            translate: self.translate,
            ..Placement::default()
        }
    }

    /// Metres per unit of the file's coordinates: `units` if given, else
    /// what the file says (`file_unit`), else millimetres.
    pub fn unit_metres(&self, file_unit: Option<f64>) -> f64 {
        match self.units {
            Some(u) => u.factor(),
            None => file_unit.unwrap_or(hexmesh::image::DEFAULT_UNIT_METRES),
        }
    }
}
