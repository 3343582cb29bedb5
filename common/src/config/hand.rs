//! Hand model files (`config/hand.toml`): bone lengths, finger radii and the palm, in the hand's
//! own frame (the wrist at the origin, fingers along -z, palm facing -y, thumb on the -x side of
//! a right hand). Hand size is data: a user measures their hand and edits the file.

use std::path::{Path, PathBuf};

use super::catalog::FileKind;
use super::reader::{parse_file, Reader};
use super::ConfigError;

/// One finger: its knuckle (MCP) in the hand frame, and its bones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerSpec {
    pub knuckle: [f64; 3],
    /// Proximal, middle, distal phalanx lengths, metres.
    pub bones: [f64; 3],
    pub radius: f64,
}

/// A whole hand model file.
#[derive(Debug, Clone, PartialEq)]
pub struct HandModelSpec {
    pub file: Option<PathBuf>,
    /// Index, middle, ring, little.
    pub fingers: [FingerSpec; 4],
    /// The thumb's base (CMC joint) in the hand frame.
    pub thumb_base: [f64; 3],
    /// Metacarpal, proximal, distal.
    pub thumb_bones: [f64; 3],
    pub thumb_radius: f64,
    pub palm_half_width: f64,
    pub palm_half_thickness: f64,
}

impl Default for HandModelSpec {
    /// An adult hand (the numbers of `config/hand.toml`).
    fn default() -> Self {
        let finger = |x: f64, z: f64, bones: [f64; 3], radius| FingerSpec {
            knuckle: [x, 0.0, z],
            bones,
            radius,
        };
        HandModelSpec {
            file: None,
            fingers: [
                finger(-0.028, -0.090, [0.045, 0.025, 0.020], 0.0090),
                finger(-0.009, -0.095, [0.050, 0.030, 0.020], 0.0090),
                finger(0.010, -0.090, [0.046, 0.028, 0.020], 0.0085),
                finger(0.028, -0.080, [0.036, 0.021, 0.018], 0.0075),
            ],
            thumb_base: [-0.030, -0.012, -0.025],
            thumb_bones: [0.040, 0.032, 0.027],
            thumb_radius: 0.010,
            palm_half_width: 0.042,
            palm_half_thickness: 0.014,
        }
    }
}

const BONE: std::ops::RangeInclusive<f64> = 0.001..=0.2;
const RADIUS: std::ops::RangeInclusive<f64> = 0.0..=0.05;
const OFFSET: std::ops::RangeInclusive<f64> = -0.3..=0.3;

impl HandModelSpec {
    /// Reads and checks a hand model file; absent keys keep the default hand's values.
    pub fn load(file: &Path) -> Result<HandModelSpec, ConfigError> {
        let table = parse_file(file)?;
        let r = Reader::root(file, FileKind::HandModel, &table);
        let mut m = HandModelSpec {
            file: Some(file.to_path_buf()),
            ..HandModelSpec::default()
        };
        if let Some(p) = r.table("palm")? {
            m.palm_half_width = p
                .f64_in("half_width", Some(m.palm_half_width), 0.005..=0.2)?
                .unwrap_or(m.palm_half_width);
            m.palm_half_thickness = p
                .f64_in("half_thickness", Some(m.palm_half_thickness), 0.002..=0.1)?
                .unwrap_or(m.palm_half_thickness);
            p.finish()?;
        }
        if let Some(t) = r.table("thumb")? {
            m.thumb_base = t.array_or::<3>("base", OFFSET, m.thumb_base)?;
            m.thumb_bones = t.array_or::<3>("bones", BONE, m.thumb_bones)?;
            m.thumb_radius = t
                .f64_in("radius", Some(m.thumb_radius), RADIUS)?
                .unwrap_or(m.thumb_radius);
            t.finish()?;
        }
        for (i, key) in ["index", "middle", "ring", "little"]
            .into_iter()
            .enumerate()
        {
            if let Some(f) = r.table(key)? {
                let spec = &mut m.fingers[i];
                spec.knuckle = f.array_or::<3>("knuckle", OFFSET, spec.knuckle)?;
                spec.bones = f.array_or::<3>("bones", BONE, spec.bones)?;
                spec.radius = f
                    .f64_in("radius", Some(spec.radius), RADIUS)?
                    .unwrap_or(spec.radius);
                f.finish()?;
            }
        }
        r.finish()?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_hand_file_is_the_default_hand() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/hand.toml");
        let m = HandModelSpec::load(&file).unwrap();
        assert_eq!(HandModelSpec { file: None, ..m }, HandModelSpec::default());
    }

    #[test]
    fn a_bad_bone_names_finger_key_and_range() {
        let dir = std::env::temp_dir().join(format!("hb-hand-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("hand.toml");
        std::fs::write(&f, "[index]\nbones = [0.045, -1, 0.02]\n").unwrap();
        let e = HandModelSpec::load(&f).unwrap_err();
        assert_eq!(e.key, "index.bones");
        assert!(
            e.problem.contains("item 1") && e.problem.contains("allowed: 0.001 to 0.2"),
            "{e}"
        );
        std::fs::write(&f, "[pinky]\nradius = 0.01\n").unwrap();
        let e = HandModelSpec::load(&f).unwrap_err();
        assert!(
            e.problem
                .contains("allowed here: index, little, middle, palm, ring, thumb"),
            "{e}"
        );
        std::fs::remove_dir_all(dir).unwrap();
    }
}
