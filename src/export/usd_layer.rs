//! A small, ordered layer builder over `openusd`'s `sdf::Data`, and the
//! encoders for `.usda`, `.usdc` and `.usdz` (all three through the crate's
//! writers).
//!
//! `sdf::Data` takes specs one by one and leaves the `primChildren` and
//! `properties` lists to the author; this builder keeps prims and properties
//! in the order they are added and fills those lists in, so a layer is
//! written in a fixed order (planning twice gives the same bytes).

use std::collections::HashMap;
use std::io::Cursor;

use openusd::sdf::{
    self, AbstractData, ChildrenKey, FieldKey, ListOp, Reference, SpecType, Specifier, Value, Variability,
};

use crate::error::{Error, Result};

/// Which encoding to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum UsdEncoding {
    /// Text.
    Usda,
    /// Binary crate (`.usdc`). openusd 0.6's crate output does not open in
    /// Pixar's USD 26.11 ("Invalid children found in primChildren"), so the
    /// export refuses it (docs/usd.md); kept for reading tests.
    Usdc,
    /// A zip package holding one text layer.
    Usdz,
}

impl UsdEncoding {
    /// The encoding of an output path, from its extension.
    pub(crate) fn of(path: &std::path::Path) -> Option<UsdEncoding> {
        match path.extension()?.to_string_lossy().to_ascii_lowercase().as_str() {
            // `.usd` may hold either encoding; throng writes text there.
            "usda" | "usd" => Some(UsdEncoding::Usda),
            "usdc" => Some(UsdEncoding::Usdc),
            "usdz" => Some(UsdEncoding::Usdz),
            _ => None,
        }
    }
}

/// One attribute or relationship.
#[derive(Clone, Debug)]
struct Prop {
    name: String,
    /// `None`: a relationship.
    type_name: Option<String>,
    uniform: bool,
    custom: bool,
    default: Option<Value>,
    samples: Vec<(f64, Value)>,
    meta: Vec<(String, Value)>,
    /// Relationship targets, or attribute connections.
    targets: Vec<String>,
}

#[derive(Clone, Debug)]
struct Prim {
    path: String,
    specifier: Specifier,
    type_name: String,
    meta: Vec<(String, Value)>,
    props: Vec<Prop>,
    children: Vec<String>,
}

/// Handle of a prim in a [`LayerBuilder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct PrimId(usize);

/// Builds one layer, prims and properties in insertion order.
#[derive(Clone, Debug, Default)]
pub(crate) struct LayerBuilder {
    prims: Vec<Prim>,
    index: HashMap<String, usize>,
    roots: Vec<String>,
    meta: Vec<(String, Value)>,
    sublayers: Vec<String>,
}

/// The name part of a prim path.
fn leaf(path: &str) -> &str {
    path.rsplit('/').next().unwrap_or(path)
}

/// A valid USD prim name from any text: `[A-Za-z0-9_]`, not starting with a
/// digit, never empty.
pub(crate) fn identifier(name: &str) -> String {
    let mut out: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
    if out.is_empty() || out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert(0, '_');
    }
    out
}

impl LayerBuilder {
    /// An empty layer.
    pub(crate) fn new() -> Self {
        Self::default()
    }

    /// Sets a layer metadata field (`metersPerUnit`, `upAxis`, ...).
    pub(crate) fn layer_meta(&mut self, key: &str, value: impl Into<Value>) {
        self.meta.push((key.to_string(), value.into()));
    }

    /// Appends a sublayer asset path (strongest first).
    pub(crate) fn sublayer(&mut self, asset: impl Into<String>) {
        self.sublayers.push(asset.into());
    }

    /// Adds a prim at an absolute `path` whose parent was added before (or is
    /// the root). Adding a path twice gives the existing prim.
    pub(crate) fn prim(&mut self, path: &str, specifier: Specifier, type_name: &str) -> PrimId {
        if let Some(&i) = self.index.get(path) {
            return PrimId(i);
        }
        let parent = &path[..path.rfind('/').unwrap_or(0)];
        match self.index.get(parent) {
            Some(&p) => self.prims[p].children.push(leaf(path).to_string()),
            None => self.roots.push(leaf(path).to_string()),
        }
        let i = self.prims.len();
        self.prims.push(Prim {
            path: path.to_string(),
            specifier,
            type_name: type_name.to_string(),
            meta: Vec::new(),
            props: Vec::new(),
            children: Vec::new(),
        });
        self.index.insert(path.to_string(), i);
        PrimId(i)
    }

    /// Whether the layer holds a prim at `path`.
    pub(crate) fn has_prim(&self, path: &str) -> bool {
        self.index.contains_key(path)
    }

    /// `def <type> "<name>"`.
    pub(crate) fn def(&mut self, path: &str, type_name: &str) -> PrimId {
        self.prim(path, Specifier::Def, type_name)
    }

    /// Sets prim metadata (`instanceable`, `kind`, `apiSchemas`, ...).
    pub(crate) fn meta(&mut self, prim: PrimId, key: &str, value: impl Into<Value>) {
        self.prims[prim.0].meta.push((key.to_string(), value.into()));
    }

    /// Applies API schemas (prepended).
    pub(crate) fn api_schemas(&mut self, prim: PrimId, names: &[&str]) {
        let op = ListOp { prepended_items: names.iter().map(|&n| n.into()).collect(), ..Default::default() };
        self.meta(prim, FieldKey::ApiSchemas.as_str(), Value::TokenListOp(op));
    }

    /// An internal reference to the prim at `target`.
    pub(crate) fn reference(&mut self, prim: PrimId, target: &str) -> Result<()> {
        let r = Reference { prim_path: sdf_path(target)?, ..Default::default() };
        let op = ListOp { prepended_items: vec![r], ..Default::default() };
        self.meta(prim, FieldKey::References.as_str(), Value::ReferenceListOp(op));
        Ok(())
    }

    fn prop(&mut self, prim: PrimId, name: &str, type_name: Option<&str>) -> &mut Prop {
        let props = &mut self.prims[prim.0].props;
        let i = match props.iter().position(|p| p.name == name) {
            Some(i) => i,
            None => {
                props.push(Prop {
                    name: name.to_string(),
                    type_name: type_name.map(str::to_string),
                    uniform: false,
                    custom: false,
                    default: None,
                    samples: Vec::new(),
                    meta: Vec::new(),
                    targets: Vec::new(),
                });
                props.len() - 1
            }
        };
        &mut props[i]
    }

    /// An attribute with a default value.
    pub(crate) fn attr(&mut self, prim: PrimId, name: &str, type_name: &str, value: impl Into<Value>) {
        self.prop(prim, name, Some(type_name)).default = Some(value.into());
    }

    /// A `uniform` attribute with a default value.
    pub(crate) fn uniform(&mut self, prim: PrimId, name: &str, type_name: &str, value: impl Into<Value>) {
        let p = self.prop(prim, name, Some(type_name));
        p.default = Some(value.into());
        p.uniform = true;
    }

    /// An attribute with time samples (times in increasing order).
    pub(crate) fn samples(&mut self, prim: PrimId, name: &str, type_name: &str, samples: Vec<(f64, Value)>) {
        self.prop(prim, name, Some(type_name)).samples = samples;
    }

    /// A constant primvar (`primvars:<name>`, interpolation `constant`).
    pub(crate) fn primvar(&mut self, prim: PrimId, name: &str, type_name: &str, value: impl Into<Value>) {
        let p = self.prop(prim, &format!("primvars:{name}"), Some(type_name));
        p.default = Some(value.into());
        p.meta.push(("interpolation".into(), Value::Token("constant".into())));
    }

    /// A time-sampled constant primvar.
    pub(crate) fn primvar_samples(&mut self, prim: PrimId, name: &str, type_name: &str, samples: Vec<(f64, Value)>) {
        let p = self.prop(prim, &format!("primvars:{name}"), Some(type_name));
        p.samples = samples;
        p.meta.push(("interpolation".into(), Value::Token("constant".into())));
    }

    /// Sets attribute metadata (`interpolation`, ...).
    pub(crate) fn attr_meta(&mut self, prim: PrimId, name: &str, key: &str, value: impl Into<Value>) {
        self.prop(prim, name, None).meta.push((key.to_string(), value.into()));
    }

    /// An output attribute connected to `source` (`</path.outputs:x>`).
    pub(crate) fn connect(&mut self, prim: PrimId, name: &str, type_name: &str, source: &str) {
        self.prop(prim, name, Some(type_name)).targets = vec![source.to_string()];
    }

    /// An attribute declared with no value (a shader output).
    pub(crate) fn declare(&mut self, prim: PrimId, name: &str, type_name: &str) {
        self.prop(prim, name, Some(type_name));
    }

    /// A relationship with explicit targets.
    pub(crate) fn rel(&mut self, prim: PrimId, name: &str, targets: Vec<String>) {
        self.prop(prim, name, None).targets = targets;
    }

    /// Number of prims.
    pub(crate) fn prim_count(&self) -> usize {
        self.prims.len()
    }

    /// The layer as `sdf::Data`.
    /// Moves the values (an export's geometry is most of its memory: it is
    /// held once, not twice).
    pub(crate) fn into_data(self) -> Result<sdf::Data> {
        let mut data = sdf::Data::new();
        let root = sdf::Path::abs_root();
        let root_spec = data.create_spec(root.clone(), SpecType::PseudoRoot);
        for (k, v) in self.meta {
            root_spec.add(&k, v);
        }
        if !self.sublayers.is_empty() {
            root_spec.add(FieldKey::SubLayers, Value::StringVec(self.sublayers.clone()));
            root_spec.add(
                FieldKey::SubLayerOffsets,
                Value::LayerOffsetVec(vec![sdf::LayerOffset::default(); self.sublayers.len()]),
            );
        }
        root_spec.add(ChildrenKey::PrimChildren, tokens(&self.roots));
        for prim in self.prims {
            let path = sdf_path(&prim.path)?;
            let spec = data.create_spec(path.clone(), SpecType::Prim);
            spec.add(FieldKey::Specifier, Value::Specifier(prim.specifier));
            if !prim.type_name.is_empty() {
                spec.add(FieldKey::TypeName, Value::Token(prim.type_name.as_str().into()));
            }
            for (k, v) in prim.meta {
                spec.add(&k, v);
            }
            if !prim.props.is_empty() {
                let names: Vec<String> = prim.props.iter().map(|p| p.name.clone()).collect();
                spec.add(ChildrenKey::PropertyChildren, tokens(&names));
            }
            if !prim.children.is_empty() {
                spec.add(ChildrenKey::PrimChildren, tokens(&prim.children));
            }
            for p in prim.props {
                let prop_path = path.append_property(&p.name).map_err(|e| bad_path(&prim.path, e))?;
                let targets = p.targets.iter().map(|t| sdf_path(t)).collect::<Result<Vec<_>>>()?;
                let spec = match &p.type_name {
                    Some(t) => {
                        let spec = data.create_spec(prop_path, SpecType::Attribute);
                        spec.add(FieldKey::TypeName, Value::Token(t.as_str().into()));
                        spec
                    }
                    None => data.create_spec(prop_path, SpecType::Relationship),
                };
                if p.custom {
                    spec.add(FieldKey::Custom, Value::Bool(true));
                }
                if p.uniform {
                    spec.add(FieldKey::Variability, Value::Variability(Variability::Uniform));
                }
                if let Some(d) = p.default {
                    spec.add(FieldKey::Default, d);
                }
                for (k, v) in p.meta {
                    spec.add(&k, v);
                }
                if !p.samples.is_empty() {
                    spec.add(FieldKey::TimeSamples, Value::TimeSamples(p.samples));
                }
                if !targets.is_empty() {
                    let key = if p.type_name.is_some() { FieldKey::ConnectionPaths } else { FieldKey::TargetPaths };
                    spec.add(key, Value::PathListOp(ListOp::explicit(targets)));
                }
            }
        }
        Ok(data)
    }

    /// The layer encoded. `name` is the layer's file name (the entry inside
    /// a `.usdz` package).
    #[cfg(test)]
    pub(crate) fn encode(&self, encoding: UsdEncoding, name: &str) -> Result<Vec<u8>> {
        self.clone().encode_with(encoding, name, &[])
    }

    /// [`LayerBuilder::encode`], with `extra` files (package-relative path,
    /// bytes) after the layer in a `.usdz` package; ignored for the other
    /// encodings.
    pub(crate) fn encode_with(self, encoding: UsdEncoding, name: &str, extra: &[(String, Vec<u8>)]) -> Result<Vec<u8>> {
        let data = self.into_data()?;
        match encoding {
            UsdEncoding::Usdz => encode_package(&data, name, extra),
            _ => encode_data(&data, encoding, name),
        }
    }
}

/// Encodes any layer data.
pub(crate) fn encode_data(data: &dyn AbstractData, encoding: UsdEncoding, name: &str) -> Result<Vec<u8>> {
    fn fail_in(name: &str) -> impl Fn(&dyn std::fmt::Display) -> Error + '_ {
        move |e| Error::invalid(name, format!("openusd cannot encode the layer: {e}"))
    }
    let f = fail_in(name);
    let fail = |e| f(&e);
    match encoding {
        UsdEncoding::Usda => {
            let text = openusd::usda::TextWriter::write_to_string(data).map_err(fail)?;
            Ok(bracket_single_api_schemas(&text).into_bytes())
        }
        UsdEncoding::Usdc => {
            let mut out = Cursor::new(Vec::new());
            openusd::usdc::CrateWriter::write(data, &mut out).map_err(fail)?;
            Ok(out.into_inner())
        }
        UsdEncoding::Usdz => encode_package(data, name, &[]),
    }
}

/// A `.usdz` package: the text layer first (the package's root layer), then
/// `extra` (package-relative path, bytes) in order.
fn encode_package(data: &dyn AbstractData, name: &str, extra: &[(String, Vec<u8>)]) -> Result<Vec<u8>> {
    fn cannot(name: &str, e: impl std::fmt::Display) -> Error {
        Error::invalid(name, format!("openusd cannot encode the package: {e}"))
    }
    let fail = |e| cannot(name, e);
    let text = encode_data(data, UsdEncoding::Usda, name)?;
    let entry = std::path::Path::new(name).with_extension("usda");
    let entry = entry.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or("root.usda".into());
    let mut archive = openusd::usdz::ArchiveWriter::new(Cursor::new(Vec::new()));
    archive.add_layer(&entry, &text).map_err(fail)?;
    for (path, bytes) in extra {
        archive.add_layer(path, bytes).map_err(fail)?;
    }
    Ok(archive.finish().map_err(fail)?.into_inner())
}

/// openusd 0.6 writes a one-item list op without brackets
/// (`prepend apiSchemas = "MaterialBindingAPI"`); Pixar's text parser takes
/// that for references but not for `apiSchemas`, so the item gets its
/// brackets back: `prepend apiSchemas = ["MaterialBindingAPI"]`.
pub(crate) fn bracket_single_api_schemas(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.split_inclusive('\n') {
        let body = line.trim_end_matches('\n');
        let trimmed = body.trim_start();
        let is_op = ["", "prepend ", "append ", "add ", "delete ", "reorder "]
            .iter()
            .any(|kw| trimmed.strip_prefix(kw).is_some_and(|r| r.starts_with("apiSchemas = \"")));
        match body.split_once("apiSchemas = ") {
            Some((head, value)) if is_op && value.starts_with('"') && value.ends_with('"') => {
                out.push_str(head);
                out.push_str("apiSchemas = [");
                out.push_str(value);
                out.push(']');
                out.push_str(&line[body.len()..]);
            }
            _ => out.push_str(line),
        }
    }
    out
}

fn tokens(names: &[String]) -> Value {
    Value::TokenVec(names.iter().map(|n| n.as_str().into()).collect())
}

fn bad_path(path: &str, e: impl std::fmt::Display) -> Error {
    Error::invalid("<usd writer>", format!("invalid USD path `{path}`: {e}"))
}

/// An `sdf::Path` from text (prim, or prim plus `.property`).
pub(crate) fn sdf_path(path: &str) -> Result<sdf::Path> {
    sdf::Path::new(path).map_err(|e| bad_path(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> LayerBuilder {
        let mut l = LayerBuilder::new();
        l.layer_meta("metersPerUnit", Value::Double(1.0));
        l.layer_meta("upAxis", Value::Token("Y".into()));
        let w = l.def("/World", "Xform");
        l.attr(w, "primvars:x", "int", Value::Int(3));
        let c = l.def("/World/Cube", "Cube");
        l.samples(c, "size", "double", vec![(1.0, Value::Double(1.0)), (2.0, Value::Double(2.0))]);
        l.rel(c, "material:binding", vec!["/World/Looks/m".into()]);
        let i = l.def("/World/Inst", "");
        l.reference(i, "/World/Cube").unwrap();
        l.meta(i, "instanceable", Value::Bool(true));
        l
    }

    #[test]
    fn text_and_binary_read_back() {
        let l = sample();
        let text = String::from_utf8(l.encode(UsdEncoding::Usda, "a.usda").unwrap()).unwrap();
        assert!(text.starts_with("#usda 1.0"));
        assert!(text.contains("upAxis = \"Y\""), "{text}");
        assert!(text.contains("size.timeSamples"), "{text}");
        assert!(text.contains("instanceable = true"), "{text}");
        // Same bytes twice.
        assert_eq!(
            l.encode(UsdEncoding::Usdc, "a.usdc").unwrap(),
            sample().encode(UsdEncoding::Usdc, "a.usdc").unwrap()
        );
        let dir = std::env::temp_dir().join(format!("throng-usd-layer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (name, enc) in [("a.usda", UsdEncoding::Usda), ("a.usdc", UsdEncoding::Usdc)] {
            let p = dir.join(name);
            std::fs::write(&p, l.encode(enc, name).unwrap()).unwrap();
            let stage = openusd::usd::Stage::open(p.to_str().unwrap()).unwrap();
            let size = stage.attribute(sdf_path("/World/Cube.size").unwrap());
            assert_eq!(size.time_sample_times().unwrap(), vec![1.0, 2.0]);
            let inst = stage.prim(sdf_path("/World/Inst").unwrap());
            assert!(inst.is_instanceable().unwrap());
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn single_api_schema_gets_brackets() {
        let t = "a (\n    prepend apiSchemas = \"MaterialBindingAPI\"\n    apiSchemas = [\"A\", \"B\"]\n)\n";
        let fixed = bracket_single_api_schemas(t);
        assert!(fixed.contains("prepend apiSchemas = [\"MaterialBindingAPI\"]\n"), "{fixed}");
        assert!(fixed.contains("apiSchemas = [\"A\", \"B\"]\n"), "{fixed}");
        assert_eq!(bracket_single_api_schemas("x = \"apiSchemas = \"\n"), "x = \"apiSchemas = \"\n");
    }

    #[test]
    fn identifiers() {
        assert_eq!(identifier("robots/chrome"), "robots_chrome");
        assert_eq!(identifier("3d"), "_3d");
        assert_eq!(identifier(""), "_");
    }
}
