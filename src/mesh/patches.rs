//! Names of the boundary patches: the six sides of the domain and the
//! surface, renameable, checked against OpenFOAM's word rules.

use crate::error::{Error, Result};
use crate::geometry::names::word_of;

use super::faces::{SIDE_PATCHES, SURFACE_PATCH};

pub use crate::geometry::names::{check_word, surface_patch_name};

/// The name of each patch id (see [`crate::mesh::faces`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PatchNames {
    names: Vec<String>,
}

impl PatchNames {
    /// The default names: `xmin xmax ymin ymax zmin zmax`, then the
    /// surface's, derived from `surface` (an STL path or a built-in name)
    /// by [`surface_patch_name`].
    pub fn new(surface: &str) -> PatchNames {
        PatchNames::with_parts(surface, &[])
    }

    /// The default names for a surface with named parts (the solids of an
    /// ASCII STL file, [`crate::geometry::Parts`]): the sides, then one
    /// patch per part, in part order, named after it (characters a patch
    /// name cannot hold become `_`; an unnamed part is called after the
    /// file stem, with `_<k>` when there are several parts; a name met
    /// twice gets `_<k>` too). Without parts, one surface patch named
    /// after the file stem.
    pub fn with_parts(surface: &str, parts: &[String]) -> PatchNames {
        let mut names: Vec<String> = SIDE_PATCHES.iter().map(|s| s.to_string()).collect();
        let stem = surface_patch_name(surface);
        if parts.is_empty() {
            names.push(stem);
            return PatchNames { names };
        }
        for (k, part) in parts.iter().enumerate() {
            let mut name = if part.trim().is_empty() {
                if parts.len() == 1 {
                    stem.clone()
                } else {
                    format!("{stem}_{k}")
                }
            } else {
                word_of(part)
            };
            if names.contains(&name) {
                name = format!("{name}_{k}");
            }
            names.push(name);
        }
        PatchNames { names }
    }

    /// Name of patch `p`.
    pub fn name(&self, p: usize) -> &str {
        &self.names[p]
    }

    /// Every name, in patch-id order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The id of the patch called `name`.
    pub fn id(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Renames patch `from` (its current name, or `surface` for the surface
    /// patch) to `to`. Errors: an unknown patch, a name OpenFOAM would not
    /// accept, or one another patch already has.
    pub fn rename(&mut self, from: &str, to: &str) -> Result<()> {
        let id = match self.id(from) {
            Some(i) => i,
            None if from == "surface" => SURFACE_PATCH as usize,
            None => {
                return Err(Error::invalid(format!(
                    "unknown patch '{from}': the patches are {}",
                    self.names.join(", ")
                )))
            }
        };
        check_word(to)?;
        if let Some(other) = self.id(to).filter(|&o| o != id) {
            return Err(Error::invalid(format!(
                "patch name '{to}' is already patch {other}'s: names must be unique"
            )));
        }
        self.names[id] = to.to_string();
        Ok(())
    }

    /// Applies `renames` (`from=to` pairs) together: each `from` is a
    /// patch's default name (or `surface`), so the order does not matter.
    pub fn renamed<'a>(
        self,
        renames: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<PatchNames> {
        let original = self.clone();
        let mut out = self;
        let mut done: Vec<usize> = Vec::new();
        for (from, to) in renames {
            let id = match original.id(from) {
                Some(i) => i,
                None if from == "surface" => SURFACE_PATCH as usize,
                None => {
                    return Err(Error::invalid(format!(
                        "unknown patch '{from}': the patches are {}",
                        original.names.join(", ")
                    )))
                }
            };
            if done.contains(&id) {
                return Err(Error::invalid(format!("patch '{from}' is renamed twice")));
            }
            check_word(to)?;
            done.push(id);
            out.names[id] = to.to_string();
        }
        for (i, n) in out.names.iter().enumerate() {
            if let Some(j) = out.names[..i].iter().position(|m| m == n) {
                return Err(Error::invalid(format!(
                    "patches {j} and {i} are both called '{n}': names must be unique"
                )));
            }
        }
        Ok(out)
    }
}

impl Default for PatchNames {
    fn default() -> Self {
        PatchNames::new("surface")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_renames() {
        let p = PatchNames::new("../shared/data/bunny.stl");
        assert_eq!(p.name(6), "bunny");
        assert_eq!(p.name(0), "xmin");
        assert_eq!(PatchNames::new("sphere").name(6), "sphere");
        assert_eq!(PatchNames::new("my model (2).stl").name(6), "my_model__2_");
        assert_eq!(PatchNames::new("3d.stl").name(6), "_3d");
        assert_eq!(PatchNames::new("xmin.stl").name(6), "xmin_surface");
        let p = p
            .renamed([("xmin", "inlet"), ("xmax", "outlet"), ("surface", "wall")])
            .unwrap();
        let swapped = PatchNames::new("sphere")
            .renamed([("xmin", "xmax"), ("xmax", "xmin")])
            .unwrap();
        assert_eq!(swapped.names()[..2], ["xmax", "xmin"]);
        let e = PatchNames::new("sphere")
            .renamed([("xmin", "ymin")])
            .unwrap_err();
        assert!(e.message().contains("unique"), "{e}");
        assert_eq!(p.names()[..2], ["inlet", "outlet"]);
        assert_eq!(p.name(6), "wall");
        let mut q = p.clone();
        assert!(q
            .rename("xmin", "x")
            .unwrap_err()
            .message()
            .contains("unknown patch"));
        assert!(q
            .rename("inlet", "outlet")
            .unwrap_err()
            .message()
            .contains("unique"));
        assert!(q
            .rename("inlet", "in let")
            .unwrap_err()
            .message()
            .contains("not a valid"));
        assert!(q.rename("inlet", "").is_err());
        assert!(q.rename("inlet", "a;b").is_err());
        assert!(q.rename("inlet", "1a").is_err());
        assert_eq!(q, p, "a failed rename changes nothing");
    }

    #[test]
    fn parts_become_patches() {
        let parts = [
            "hull".to_string(),
            "deck house".into(),
            "".into(),
            "hull2".into(),
        ];
        let p = PatchNames::with_parts("boat.stl", &parts);
        assert_eq!(p.names()[6..], ["hull", "deck_house", "boat_2", "hull2"]);
        let one = PatchNames::with_parts("boat.stl", &["".to_string()]);
        assert_eq!(one.names()[6..], ["boat"]);
        let clash =
            PatchNames::with_parts("a.stl", &["xmin".to_string(), "b c".into(), "b_c".into()]);
        assert_eq!(clash.names()[6..], ["xmin_surface", "b_c", "b_c_2"]);
        for n in clash.names() {
            check_word(n).unwrap();
        }
        let renamed = p.renamed([("deck_house", "house")]).unwrap();
        assert_eq!(renamed.name(7), "house");
    }
}
