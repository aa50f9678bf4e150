//! Boundary layers: the `[mesh]` settings and the `[[layers]]` tables
//! per patch, checked and resolved into the OpenFOAM writer's plan.

use serde::{Deserialize, Serialize};

use super::{Config, ConfigError};
use crate::io::openfoam::{LayerPlan, LayerSpec, LayerThickness};
use crate::mesh::faces::SURFACE_PATCH;
use crate::mesh::patches::PatchNames;

/// `[[layers]]`: the boundary layers of one wall patch; unset keys take
/// the `[mesh]` settings.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PatchLayers {
    /// The patch, by its name in the OpenFOAM case.
    pub patch: String,
    /// Layers (1 or more).
    pub layers: Option<u32>,
    /// Each layer's height over the one before it.
    pub expansion: Option<f64>,
    /// The first layer's height.
    pub first_layer: Option<f64>,
    /// The last layer's height.
    pub final_layer: Option<f64>,
    /// All layers together.
    pub thickness: Option<f64>,
}

/// The one thickness of `first`, `last`, `total`; `Err` naming the two
/// given when more than one is.
fn thickness(
    [first, last, total]: [Option<f64>; 3],
    names: [&str; 3],
) -> Result<Option<LayerThickness>, String> {
    let given: Vec<&str> = [first, last, total]
        .iter()
        .zip(names)
        .filter(|(v, _)| v.is_some())
        .map(|(_, n)| n)
        .collect();
    if given.len() > 1 {
        return Err(format!(
            "gets {} and {}: give one thickness",
            given[0], given[1]
        ));
    }
    Ok(first
        .map(LayerThickness::First)
        .or(last.map(LayerThickness::Final))
        .or(total.map(LayerThickness::Total)))
}

impl Config {
    /// Whether the OpenFOAM case gets boundary layers (`mesh.layers` or a
    /// `[[layers]]` table).
    pub fn layers_on(&self) -> bool {
        self.mesh.layers.is_some() || !self.layers.is_empty()
    }

    /// Whether the OpenFOAM case gets the wall layer (asked for, or under
    /// boundary layers).
    pub fn wall_layer(&self) -> bool {
        self.mesh.wall_layer || self.layers_on()
    }

    /// The key errors about the layers name.
    pub(super) fn layers_key(&self) -> &'static str {
        match self.mesh.layers {
            Some(_) => "mesh.layers",
            None => "layers",
        }
    }

    /// The global thickness, if one is given.
    fn global_thickness(&self) -> Result<Option<LayerThickness>, ConfigError> {
        let m = &self.mesh;
        thickness(
            [m.first_layer, m.final_layer, m.layer_thickness],
            [
                "{mesh.first_layer}",
                "{mesh.final_layer}",
                "{mesh.layer_thickness}",
            ],
        )
        .map_err(|e| ConfigError::new("mesh.first_layer", e))
    }

    /// The layer settings' consistency (their ranges are the options'):
    /// one thickness each, relative thicknesses below 1, every table's
    /// values in range and complete with the global ones.
    pub(super) fn check_layers(&self) -> Result<(), ConfigError> {
        let global = self.global_thickness()?;
        let relative = self.mesh.relative_sizes;
        let key = self.layers_key();
        let check_spec = |what: &str, s: &LayerSpec| -> Result<(), String> {
            let t = match s.thickness {
                LayerThickness::First(t) | LayerThickness::Final(t) | LayerThickness::Total(t) => t,
            };
            if !(t.is_finite() && t > 0.0) {
                return Err(format!("{what}gives the thickness {t}: it must be above 0"));
            }
            if relative && t >= 1.0 {
                return Err(format!(
                    "{what}gives the thickness {t} with {{mesh.relative_sizes}}: a fraction of the \
                     wall cell must be below 1"
                ));
            }
            if s.layers < 1 {
                return Err(format!("{what}asks for {} layers: at least 1", s.layers));
            }
            if !(s.expansion.is_finite() && s.expansion > 0.0) {
                return Err(format!(
                    "{what}gives the expansion {}: it must be above 0",
                    s.expansion
                ));
            }
            Ok(())
        };
        if let Some(n) = self.mesh.layers {
            let spec = LayerSpec {
                layers: n,
                expansion: self.mesh.layer_expansion,
                thickness: global.ok_or_else(|| {
                    ConfigError::new(
                        key,
                        "needs one of {mesh.first_layer}, {mesh.final_layer} and \
                         {mesh.layer_thickness}",
                    )
                })?,
                relative,
            };
            check_spec("", &spec).map_err(|m| ConfigError::new(key, m))?;
        }
        for (i, t) in self.layers.iter().enumerate() {
            let what = format!("table {} (patch '{}') ", i + 1, t.patch);
            let spec = self
                .patch_spec(t, global)
                .map_err(|m| ConfigError::new("layers", format!("{what}{m}")))?;
            check_spec(&what, &spec).map_err(|m| ConfigError::new("layers", m))?;
            if self.layers[..i].iter().any(|o| o.patch == t.patch) {
                return Err(ConfigError::new(
                    "layers",
                    format!("{what}names a patch an earlier table names"),
                ));
            }
        }
        Ok(())
    }

    /// The layer settings' ranges and consistency, as an error naming the
    /// case file's keys (the C API's check).
    pub fn check_layer_settings(&self) -> crate::Result<()> {
        let keys = [
            ("mesh.layers", self.mesh.layers.map(f64::from)),
            ("mesh.layer_expansion", Some(self.mesh.layer_expansion)),
            ("mesh.first_layer", self.mesh.first_layer),
            ("mesh.final_layer", self.mesh.final_layer),
            ("mesh.layer_thickness", self.mesh.layer_thickness),
        ];
        for (key, v) in keys {
            if let Some(v) = v {
                super::options::check_key(key, key, v)?;
            }
        }
        self.check_layers()
            .map_err(|e| crate::Error::invalid(e.render(|k| k.to_string())))
    }

    /// A `[[layers]]` table completed with the global settings.
    fn patch_spec(
        &self,
        t: &PatchLayers,
        global: Option<LayerThickness>,
    ) -> Result<LayerSpec, String> {
        let own = thickness(
            [t.first_layer, t.final_layer, t.thickness],
            ["first_layer", "final_layer", "thickness"],
        )?;
        Ok(LayerSpec {
            layers: t
                .layers
                .or(self.mesh.layers)
                .ok_or("sets no layers, and neither does {mesh.layers}")?,
            expansion: t.expansion.unwrap_or(self.mesh.layer_expansion),
            thickness: own.or(global).ok_or(
                "gives no thickness, and none of {mesh.first_layer}, {mesh.final_layer} and \
                 {mesh.layer_thickness} is set",
            )?,
            relative: self.mesh.relative_sizes,
        })
    }

    /// The boundary layers per wall patch of a case with patches `names`
    /// (`None` without layers). A `[[layers]]` table naming no wall patch
    /// is an error. Call after [`Config::validate`].
    pub fn layer_plan(&self, names: &PatchNames) -> crate::Result<Option<LayerPlan>> {
        if !self.layers_on() {
            return Ok(None);
        }
        let bad = |m: String| crate::Error::invalid(m);
        let global = self.global_thickness().map_err(|e| bad(e.message))?;
        let walls = SURFACE_PATCH as usize..names.names().len();
        for t in &self.layers {
            match names.id(&t.patch) {
                Some(q) if walls.contains(&q) => {}
                Some(_) => {
                    return Err(bad(format!(
                        "[[layers]] names the patch '{}', a side of the domain: layers grow on \
                         the wall patches ({})",
                        t.patch,
                        names.names()[walls.clone()].join(", ")
                    )))
                }
                None => {
                    return Err(bad(format!(
                        "[[layers]] names the patch '{}', which the case does not have: its wall \
                         patches are {}",
                        t.patch,
                        names.names()[walls.clone()].join(", ")
                    )))
                }
            }
        }
        let global_spec = match (self.mesh.layers, global) {
            (Some(n), Some(thickness)) => Some(LayerSpec {
                layers: n,
                expansion: self.mesh.layer_expansion,
                thickness,
                relative: self.mesh.relative_sizes,
            }),
            _ => None,
        };
        let mut patches = Vec::with_capacity(walls.len());
        for q in walls {
            let spec = match self.layers.iter().find(|t| t.patch == names.name(q)) {
                Some(t) => Some(self.patch_spec(t, global).map_err(bad)?),
                None => global_spec,
            };
            patches.push(spec);
        }
        Ok(Some(LayerPlan { patches }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> Config {
        let mut c = Config::default();
        (c.mesh.layers, c.mesh.first_layer, c.mesh.layer_expansion) = (Some(3), Some(0.01), 1.2);
        c
    }

    #[test]
    fn tables_override_the_global_setting_per_patch() {
        let names = PatchNames::with_parts("s", &["hull".into(), "keel".into()]);
        let mut c = config();
        c.layers = vec![PatchLayers {
            patch: "keel".into(),
            layers: Some(2),
            thickness: Some(0.05),
            ..PatchLayers::default()
        }];
        c.check_layers().unwrap();
        let plan = c.layer_plan(&names).unwrap().unwrap();
        assert_eq!(plan.patches.len(), 2);
        let hull = plan.patches[0].unwrap();
        assert_eq!(
            (hull.layers, hull.thickness),
            (3, LayerThickness::First(0.01))
        );
        let keel = plan.patches[1].unwrap();
        assert_eq!(keel.layers, 2);
        assert_eq!(keel.expansion, 1.2);
        assert_eq!(keel.thickness, LayerThickness::Total(0.05));
        // Without the global count only the table's patch gets layers.
        c.mesh.layers = None;
        let plan = c.layer_plan(&names).unwrap().unwrap();
        assert!(plan.patches[0].is_none() && plan.patches[1].is_some());
    }

    #[test]
    fn bad_settings_and_unknown_patches_are_refused() {
        let names = PatchNames::new("sphere");
        let mut c = config();
        c.mesh.final_layer = Some(0.1);
        assert!(c
            .check_layers()
            .unwrap_err()
            .message
            .contains("one thickness"));
        let mut c = config();
        (c.mesh.relative_sizes, c.mesh.first_layer) = (true, Some(1.0));
        assert!(c.check_layers().unwrap_err().message.contains("below 1"));
        let mut c = config();
        c.mesh.layers = Some(0);
        assert!(c.check_layers().unwrap_err().message.contains("at least 1"));
        for (patch, word) in [("wing", "does not have"), ("xmin", "a side")] {
            let mut c = config();
            c.layers = vec![PatchLayers {
                patch: patch.into(),
                ..PatchLayers::default()
            }];
            let e = c.layer_plan(&names).unwrap_err();
            assert!(e.message().contains(word), "{e}");
        }
    }
}
