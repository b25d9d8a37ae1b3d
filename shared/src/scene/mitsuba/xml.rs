//! Reading Mitsuba 3 XML into a `Document`: `$name` substitution, `<default>`, `<include>`, `<path>`,
//! `<alias>`, typed values, transforms, and `id`/`<ref>` resolution with cycle and duplicate checks.

use super::document::{resolve_in, Category, Child, Document, Param, Plugin, Value};
use super::error::{MitsubaError, SourcePos};
use super::files::FileSource;
use super::spectrum::Spectrum;
use super::transform;
use glam::{DMat4, DVec3};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The most `<include>` levels a file may nest, beyond which it is refused (a cycle is refused sooner).
const MAX_INCLUDE_DEPTH: usize = 32;
/// The deepest nesting of plugins, and of references through plugins, that is read: far beyond real scenes,
/// and shallow enough that hostile files cannot exhaust the stack of the recursive reading.
const MAX_NESTING: usize = 100;
/// The largest scene file read (meshes and textures are separate files).
const MAX_FILE_BYTES: u64 = 64 << 20;

/// Reads the scene file at `path` and every file it includes. `defines` set `$name` parameters and override
/// the file's `<default>`s (Mitsuba's `-D name=value`).
pub fn read_file(path: &Path, defines: &[(String, String)]) -> Result<Document, MitsubaError> {
    let mut reader = Reader::new(path, defines, FileSource::Disk);
    let top = reader.read_included(path, &SourcePos::file_start(path), None, None)?;
    reader.finish(path, top)
}

/// Reads a scene from `text` as if it were the file `path` (whose folder includes and files are relative to).
pub fn read_str(text: &str, path: &Path, defines: &[(String, String)]) -> Result<Document, MitsubaError> {
    read_str_from(text, path, defines, FileSource::Disk)
}

/// `read_str` with the included and spectrum files read from `files` (a job's files on a worker).
pub fn read_str_from(
    text: &str,
    path: &Path,
    defines: &[(String, String)],
    files: FileSource,
) -> Result<Document, MitsubaError> {
    let mut reader = Reader::new(path, defines, files);
    let mut top = Vec::new();
    reader.read_text(text, path, &mut top, None)?;
    reader.finish(path, top)
}

/// A plugin element as read, before references are resolved.
struct RawPlugin {
    category: Category,
    kind: String,
    id: Option<String>,
    position: SourcePos,
    element: String,
    params: Vec<Param>,
    children: Vec<RawChild>,
    /// Names used by parameters and named children, to refuse one given twice.
    names: HashMap<String, SourcePos>,
}

struct RawChild {
    name: Option<String>,
    position: SourcePos,
    target: Target,
}

enum Target {
    /// A plugin written in place: its index among the reader's plugins.
    Inline(usize),
    /// `<ref id="...">`, with the element for messages.
    Reference { id: String, element: String },
}

/// Where the elements being read go: the top level of the scene or a plugin's children.
type Parent = Option<usize>;

struct Reader<'f> {
    /// Where included and spectrum files are read from.
    files: FileSource<'f>,
    /// The included and spectrum files read, in order.
    read: Vec<PathBuf>,
    /// `$name` parameters: the caller's defines, then `<default>`s in document order (the first one wins).
    variables: HashMap<String, String>,
    /// The caller's defines, to refuse one that the scene never uses (a typo, as Mitsuba also refuses).
    defines: Vec<String>,
    /// The names substituted so far.
    used: RefCell<HashSet<String>>,
    plugins: Vec<RawPlugin>,
    ids: HashMap<String, usize>,
    aliases: HashMap<String, (String, SourcePos, String)>,
    /// Canonical paths of the files being read, outermost first, for the include cycle check.
    include_stack: Vec<PathBuf>,
    search_paths: Vec<PathBuf>,
    /// The scene's folder, where `filename`s are looked up last.
    scene_folder: PathBuf,
    version: Option<String>,
    /// How many plugins enclose the element being read.
    nesting: usize,
}

/// One element's tag, position and attributes after `$name` substitution.
pub(super) struct Attributes {
    pub tag: String,
    pub position: SourcePos,
    /// The element as written (tag with its `type`, `name` or `id`), for messages.
    pub element: String,
    values: Vec<(String, String)>,
}

impl Attributes {
    /// An error at this element.
    pub fn error(&self, message: impl Into<String>) -> MitsubaError {
        MitsubaError::at(&self.position, self.element.clone(), message)
    }

    /// The attribute `name`, substituted.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.values.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    /// The attribute `name`, which must be present.
    pub fn required(&self, name: &str) -> Result<&str, MitsubaError> {
        self.get(name).ok_or_else(|| self.error(format!("the attribute `{name}` is missing")))
    }

    /// Refuses attributes other than `allowed`, which Mitsuba refuses too (a typo would be ignored otherwise).
    pub fn allow_only(&self, allowed: &[&str]) -> Result<(), MitsubaError> {
        match self.values.iter().find(|(n, _)| !allowed.contains(&n.as_str())) {
            Some((name, _)) => Err(self.error(format!(
                "unexpected attribute `{name}` (<{}> takes {})",
                self.tag,
                allowed.iter().map(|a| format!("`{a}`")).collect::<Vec<_>>().join(", ")
            ))),
            None => Ok(()),
        }
    }

    /// The attribute `name` as one finite number.
    pub fn number(&self, name: &str) -> Result<Option<f64>, MitsubaError> {
        self.get(name).map(|text| parse_number(text).map_err(|m| self.error(format!("`{name}`: {m}")))).transpose()
    }

    pub fn required_number(&self, name: &str) -> Result<f64, MitsubaError> {
        self.required(name)?;
        Ok(self.number(name)?.expect("present"))
    }

    /// The attribute `name` as numbers separated by commas or spaces.
    pub fn numbers(&self, name: &str) -> Result<Option<Vec<f64>>, MitsubaError> {
        let Some(text) = self.get(name) else { return Ok(None) };
        let values: Result<Vec<f64>, String> = split_list(text).map(parse_number).collect();
        let values = values.map_err(|m| self.error(format!("`{name}`: {m}")))?;
        if values.is_empty() {
            return Err(self.error(format!("`{name}` is empty")));
        }
        Ok(Some(values))
    }

    pub fn required_numbers(&self, name: &str) -> Result<Vec<f64>, MitsubaError> {
        self.required(name)?;
        Ok(self.numbers(name)?.expect("present"))
    }

    /// The attribute `name` as a 3-vector "x, y, z".
    pub fn vector(&self, name: &str) -> Result<Option<DVec3>, MitsubaError> {
        match self.numbers(name)? {
            None => Ok(None),
            Some(v) if v.len() == 3 => Ok(Some(DVec3::new(v[0], v[1], v[2]))),
            Some(v) => Err(self.error(format!("`{name}` has three numbers \"x, y, z\", not {}", v.len()))),
        }
    }

    pub fn required_vector(&self, name: &str) -> Result<DVec3, MitsubaError> {
        self.required(name)?;
        Ok(self.vector(name)?.expect("present"))
    }
}

fn split_list(text: &str) -> impl Iterator<Item = &str> {
    text.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty())
}

fn parse_number(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("\"{text}\" is not a finite number")),
        Err(_) => Err(format!("\"{text}\" is not a number")),
    }
}

impl<'f> Reader<'f> {
    fn new(path: &Path, defines: &[(String, String)], files: FileSource<'f>) -> Reader<'f> {
        Reader {
            files,
            read: Vec::new(),
            variables: defines.iter().cloned().collect(),
            defines: defines.iter().map(|(name, _)| name.clone()).collect(),
            used: RefCell::new(HashSet::new()),
            plugins: Vec::new(),
            ids: HashMap::new(),
            aliases: HashMap::new(),
            include_stack: Vec::new(),
            search_paths: Vec::new(),
            scene_folder: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            version: None,
            nesting: 0,
        }
    }

    /// Reads the file at `path` (the main file, or an include from the element `from`) into `parent`; returns
    /// the top-level plugins it added when `parent` is the top level.
    fn read_included(
        &mut self,
        path: &Path,
        from: &SourcePos,
        element: Option<&str>,
        parent: Parent,
    ) -> Result<Vec<usize>, MitsubaError> {
        let cannot =
            |what: String| MitsubaError { position: from.clone(), element: element.map(str::to_string), message: what };
        let canonical = self.files.identity(path).map_err(cannot)?;
        if let Some(first) = self.include_stack.iter().position(|p| *p == canonical) {
            let chain: Vec<String> =
                self.include_stack[first..].iter().chain([&canonical]).map(|p| p.display().to_string()).collect();
            return Err(cannot(format!("include cycle: {}", chain.join(" includes "))));
        }
        if self.include_stack.len() >= MAX_INCLUDE_DEPTH {
            return Err(cannot(format!("more than {MAX_INCLUDE_DEPTH} nested includes")));
        }
        let bytes = self.files.read(path).map_err(cannot)?;
        let size = bytes.len() as u64;
        if size > MAX_FILE_BYTES {
            return Err(cannot(format!(
                "{} is {size} bytes, over the {MAX_FILE_BYTES} read for a scene file",
                path.display()
            )));
        }
        let text = String::from_utf8(bytes.into_owned())
            .map_err(|_| cannot(format!("{} is not UTF-8 text", path.display())))?;
        if element.is_some() {
            // An included file (the scene file itself is read from no element).
            self.read.push(path.to_path_buf());
        }
        self.include_stack.push(canonical);
        let mut top = Vec::new();
        let result = self.read_text(&text, path, &mut top, parent);
        self.include_stack.pop();
        result.map(|()| top)
    }

    fn read_text(&mut self, text: &str, path: &Path, top: &mut Vec<usize>, parent: Parent) -> Result<(), MitsubaError> {
        let file = Arc::new(path.to_path_buf());
        let document = roxmltree::Document::parse(text).map_err(|e| {
            let pos = e.pos();
            MitsubaError::in_file(
                SourcePos { file: file.clone(), line: pos.row, column: pos.col },
                format!("not well-formed XML: {e}"),
            )
        })?;
        let line_starts = std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect();
        let source = Source { file, text, line_starts };
        let root = document.root_element();
        let attributes = self.attributes(&source, root)?;
        if attributes.tag != "scene" {
            return Err(attributes.error("the root element of a Mitsuba scene file is <scene version=\"3.0.0\">"));
        }
        attributes.allow_only(&["version"])?;
        let version = attributes
            .get("version")
            .ok_or_else(|| attributes.error("the attribute `version` is missing (e.g. version=\"3.0.0\")"))?;
        let major = version.split('.').next().unwrap_or_default();
        if major != "2" && major != "3" {
            return Err(attributes.error(format!(
                "scene version {version}: this reader takes the Mitsuba 2 and 3 format (version 2.x or 3.x); \
                 Mitsuba 0.6 files need converting first"
            )));
        }
        if self.version.is_none() {
            self.version = Some(version.to_string());
        }
        for node in root.children().filter(roxmltree::Node::is_element) {
            self.read_element(&source, node, parent, top)?;
        }
        Ok(())
    }

    /// The tag, position and substituted attributes of `node`.
    fn attributes(&self, source: &Source, node: roxmltree::Node) -> Result<Attributes, MitsubaError> {
        let tag = node.tag_name().name().to_string();
        let position = source.position(node.range().start);
        let mut element = format!("<{tag}");
        for key in ["type", "name", "id", "filename"] {
            if let Some(value) = node.attribute(key) {
                element.push_str(&format!(" {key}=\"{value}\""));
            }
        }
        element.push('>');
        let mut values = Vec::new();
        for attribute in node.attributes() {
            let value = substitute(attribute.value(), &self.variables, &mut self.used.borrow_mut())
                .map_err(|m| MitsubaError::at(&position, element.clone(), format!("`{}`: {m}", attribute.name())))?;
            values.push((attribute.name().to_string(), value));
        }
        Ok(Attributes { tag, position, element, values })
    }

    /// Reads one element into `parent` (None: the scene's top level, whose plugins go to `top`).
    fn read_element(
        &mut self,
        source: &Source,
        node: roxmltree::Node,
        parent: Parent,
        top: &mut Vec<usize>,
    ) -> Result<(), MitsubaError> {
        let attributes = self.attributes(source, node)?;
        let tag = attributes.tag.as_str();
        match tag {
            "default" => {
                attributes.allow_only(&["name", "value"])?;
                let name = attributes.required("name")?;
                let value = attributes.required("value")?;
                if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                    return Err(attributes.error(format!("`{name}` is not a parameter name (letters, digits, _)")));
                }
                self.variables.entry(name.to_string()).or_insert_with(|| value.to_string());
                Ok(())
            }
            "include" => {
                attributes.allow_only(&["filename"])?;
                let name = attributes.required("filename")?;
                let here = source.file.parent().unwrap_or(Path::new("."));
                let mut path = here.join(name);
                if !self.files.exists(&path) {
                    path = resolve_in(name, &self.search_paths, &self.scene_folder, |p| self.files.exists(p));
                }
                if !self.files.exists(&path) {
                    return Err(
                        attributes.error(format!("the included file {} does not exist", here.join(name).display()))
                    );
                }
                let added = self.read_included(&path, &attributes.position, Some(&attributes.element), parent)?;
                top.extend(added);
                Ok(())
            }
            "path" => {
                attributes.allow_only(&["value"])?;
                let value = attributes.required("value")?;
                let folder = source.file.parent().unwrap_or(Path::new(".")).join(value);
                if !self.files.is_dir(&folder) {
                    return Err(attributes.error(format!("the folder {} does not exist", folder.display())));
                }
                let folder = match self.files {
                    FileSource::Disk => folder.canonicalize().unwrap_or(folder),
                    FileSource::Memory(_) => folder,
                };
                self.search_paths.insert(0, folder);
                Ok(())
            }
            "alias" => {
                attributes.allow_only(&["id", "as"])?;
                let id = attributes.required("id")?.to_string();
                let alias = attributes.required("as")?.to_string();
                self.claim_id(&alias, &attributes)?;
                self.aliases.insert(alias, (id, attributes.position.clone(), attributes.element.clone()));
                Ok(())
            }
            "ref" => {
                attributes.allow_only(&["id", "name"])?;
                let id = attributes.required("id")?.to_string();
                let Some(parent) = parent else {
                    return Err(attributes.error("a <ref> belongs inside a plugin (e.g. a bsdf reference in a shape)"));
                };
                let name = attributes.get("name").map(str::to_string);
                self.add_child(parent, name, &attributes, Target::Reference { id, element: attributes.element.clone() })
            }
            "transform" | "float" | "integer" | "boolean" | "string" | "rgb" | "point" | "vector" => {
                self.read_value(source, node, &attributes, parent)
            }
            "spectrum" if attributes.get("type").is_none() => self.read_value(source, node, &attributes, parent),
            _ => {
                let Some(category) = Category::from_tag(tag) else {
                    let hint = if matches!(tag, "translate" | "rotate" | "scale" | "matrix" | "lookat") {
                        " (transform elements belong inside <transform name=\"to_world\">)"
                    } else {
                        ""
                    };
                    return Err(attributes.error(format!("unknown element <{tag}>{hint}")));
                };
                self.read_plugin(source, node, attributes, category, parent, top)
            }
        }
    }

    fn read_plugin(
        &mut self,
        source: &Source,
        node: roxmltree::Node,
        attributes: Attributes,
        category: Category,
        parent: Parent,
        top: &mut Vec<usize>,
    ) -> Result<(), MitsubaError> {
        attributes.allow_only(&["type", "id", "name"])?;
        let kind =
            attributes.get("type").ok_or_else(|| attributes.error("the attribute `type` is missing"))?.to_string();
        if kind.is_empty() {
            return Err(attributes.error("the attribute `type` is empty"));
        }
        let id = attributes.get("id").map(str::to_string);
        let index = self.plugins.len();
        if let Some(id) = &id {
            self.claim_id(id, &attributes)?;
            self.ids.insert(id.clone(), index);
        }
        self.plugins.push(RawPlugin {
            category,
            kind,
            id,
            position: attributes.position.clone(),
            element: attributes.element.clone(),
            params: Vec::new(),
            children: Vec::new(),
            names: HashMap::new(),
        });
        match parent {
            Some(parent) => {
                let name = attributes.get("name").map(str::to_string);
                self.add_child(parent, name, &attributes, Target::Inline(index))?;
            }
            None => top.push(index),
        }
        if self.nesting == MAX_NESTING {
            return Err(attributes.error(format!("plugins nest deeper than {MAX_NESTING} levels here")));
        }
        self.nesting += 1;
        let mut nested_top = Vec::new();
        let result = node
            .children()
            .filter(roxmltree::Node::is_element)
            .try_for_each(|child| self.read_element(source, child, Some(index), &mut nested_top));
        self.nesting -= 1;
        result
    }

    /// Refuses an id (or alias) given twice.
    fn claim_id(&self, id: &str, attributes: &Attributes) -> Result<(), MitsubaError> {
        if id.is_empty() {
            return Err(attributes.error("an empty id"));
        }
        let earlier = self.ids.get(id).map(|&i| &self.plugins[i].position).or(self.aliases.get(id).map(|a| &a.1));
        match earlier {
            Some(earlier) => Err(attributes.error(format!("the id \"{id}\" is already used at {earlier}"))),
            None => Ok(()),
        }
    }

    fn claim_name(&mut self, parent: usize, name: &str, attributes: &Attributes) -> Result<(), MitsubaError> {
        let plugin = &mut self.plugins[parent];
        if let Some(earlier) = plugin.names.get(name) {
            return Err(attributes.error(format!("{} has a parameter `{name}` already (at {earlier})", plugin.element)));
        }
        plugin.names.insert(name.to_string(), attributes.position.clone());
        Ok(())
    }

    fn add_child(
        &mut self,
        parent: usize,
        name: Option<String>,
        attributes: &Attributes,
        target: Target,
    ) -> Result<(), MitsubaError> {
        if let Some(name) = &name {
            self.claim_name(parent, name, attributes)?;
        }
        self.plugins[parent].children.push(RawChild { name, position: attributes.position.clone(), target });
        Ok(())
    }

    fn read_value(
        &mut self,
        source: &Source,
        node: roxmltree::Node,
        attributes: &Attributes,
        parent: Parent,
    ) -> Result<(), MitsubaError> {
        let Some(parent) = parent else {
            return Err(attributes.error(format!(
                "a <{}> value belongs inside a plugin; the scene itself takes no parameters",
                attributes.tag
            )));
        };
        let name = attributes.required("name")?.to_string();
        if name.is_empty() {
            return Err(attributes.error("the attribute `name` is empty"));
        }
        let value = self.value(source, node, attributes)?;
        self.claim_name(parent, &name, attributes)?;
        self.plugins[parent].params.push(Param { name, value, position: attributes.position.clone() });
        Ok(())
    }

    fn value(
        &mut self,
        source: &Source,
        node: roxmltree::Node,
        attributes: &Attributes,
    ) -> Result<Value, MitsubaError> {
        let tag = attributes.tag.as_str();
        if tag != "transform" {
            if let Some(child) = node.children().find(roxmltree::Node::is_element) {
                let child = self.attributes(source, child)?;
                return Err(child.error(format!("a <{tag}> value holds no elements")));
            }
        }
        match tag {
            "float" => {
                attributes.allow_only(&["name", "value"])?;
                Ok(Value::Float(attributes.required_number("value")?))
            }
            "integer" => {
                attributes.allow_only(&["name", "value"])?;
                let text = attributes.required("value")?;
                text.trim()
                    .parse::<i64>()
                    .map(Value::Integer)
                    .map_err(|_| attributes.error(format!("\"{text}\" is not an integer")))
            }
            "boolean" => {
                attributes.allow_only(&["name", "value"])?;
                let text = attributes.required("value")?;
                match text.trim().to_ascii_lowercase().as_str() {
                    "true" => Ok(Value::Boolean(true)),
                    "false" => Ok(Value::Boolean(false)),
                    _ => Err(attributes.error(format!("\"{text}\" is not a boolean: write true or false"))),
                }
            }
            "string" => {
                attributes.allow_only(&["name", "value"])?;
                Ok(Value::String(attributes.required("value")?.to_string()))
            }
            "rgb" => {
                attributes.allow_only(&["name", "value"])?;
                let values = attributes.required_numbers("value")?;
                match values[..] {
                    [v] => Ok(Value::Rgb([v; 3])),
                    [r, g, b] => Ok(Value::Rgb([r, g, b])),
                    _ => Err(attributes.error(format!("an rgb value has one or three numbers, not {}", values.len()))),
                }
            }
            "spectrum" => {
                attributes.allow_only(&["name", "value", "filename"])?;
                match (attributes.get("value"), attributes.get("filename")) {
                    (Some(_), Some(_)) => Err(attributes.error("give either value or filename, not both")),
                    (Some(text), None) => Spectrum::parse(text).map(Value::Spectrum).map_err(|m| attributes.error(m)),
                    (None, Some(name)) => {
                        let path = resolve_in(name, &self.search_paths, &self.scene_folder, |p| self.files.exists(p));
                        let spectrum = read_spectrum_file(&path, self.files).map_err(|m| attributes.error(m))?;
                        self.read.push(path);
                        Ok(Value::Spectrum(spectrum))
                    }
                    (None, None) => Err(attributes.error("a spectrum needs `value` or `filename`")),
                }
            }
            "point" | "vector" => {
                attributes.allow_only(&["name", "value", "x", "y", "z"])?;
                let has_xyz = ["x", "y", "z"].iter().any(|a| attributes.get(a).is_some());
                let v = match attributes.vector("value")? {
                    Some(_) if has_xyz => return Err(attributes.error("give either value or x, y, z, not both")),
                    Some(v) => v,
                    None => DVec3::new(
                        attributes.required_number("x")?,
                        attributes.required_number("y")?,
                        attributes.required_number("z")?,
                    ),
                };
                Ok(if tag == "point" { Value::Point(v) } else { Value::Vector(v) })
            }
            "transform" => {
                attributes.allow_only(&["name"])?;
                let mut matrix = DMat4::IDENTITY;
                for child in node.children().filter(roxmltree::Node::is_element) {
                    let child = self.attributes(source, child)?;
                    matrix = transform::element_matrix(&child)? * matrix;
                }
                Ok(Value::Transform(matrix))
            }
            _ => unreachable!("read_element passes value tags only"),
        }
    }

    /// Resolves references and sorts the top-level plugins into a `Document`.
    fn finish(self, path: &Path, top: Vec<usize>) -> Result<Document, MitsubaError> {
        if let Some(unused) = self.defines.iter().find(|name| !self.used.borrow().contains(*name)) {
            return Err(MitsubaError::in_file(
                SourcePos::file_start(path),
                format!("the define `{unused}` is used nowhere in the scene (no attribute says `${unused}`)"),
            ));
        }
        let mut resolver =
            Resolver { reader: &self, done: vec![None; self.plugins.len()], in_progress: HashSet::new() };
        let mut document = Document {
            path: path.to_path_buf(),
            version: self.version.clone().unwrap_or_default(),
            search_paths: self.search_paths.clone(),
            files: self.read.clone(),
            ..Document::default()
        };
        // Every plugin is resolved, also those no one references, so that a dangling ref anywhere is refused.
        for index in 0..self.plugins.len() {
            resolver.resolve(index, 0)?;
        }
        for (alias, (id, position, element)) in &self.aliases {
            resolver.lookup(id, position, element).map_err(|_| {
                MitsubaError::at(
                    position,
                    element.clone(),
                    format!("the alias `{alias}` names `{id}`, which no plugin has"),
                )
            })?;
        }
        for index in top {
            let plugin = resolver.resolve(index, 0)?;
            match plugin.category {
                Category::Sensor => document.sensors.push(plugin),
                Category::Integrator => {
                    if let Some(first) = &document.integrator {
                        return Err(plugin.error(format!("a second integrator (the first is at {})", first.position)));
                    }
                    document.integrator = Some(plugin);
                }
                Category::Shape => document.shapes.push(plugin),
                Category::Emitter => document.emitters.push(plugin),
                Category::Bsdf => document.bsdfs.push(plugin),
                Category::Texture => document.textures.push(plugin),
                _ => document.others.push(plugin),
            }
        }
        Ok(document)
    }
}

struct Source<'input> {
    file: Arc<PathBuf>,
    text: &'input str,
    /// Byte offsets where lines start, to find positions in logarithmic time (a scan from the start of the file
    /// for each element would take quadratic time on large files).
    line_starts: Vec<usize>,
}

impl Source<'_> {
    /// The 1-based line and column (in characters) of a byte offset.
    fn position(&self, offset: usize) -> SourcePos {
        let line = self.line_starts.partition_point(|&start| start <= offset);
        let start = self.line_starts[line - 1];
        let column = self.text.get(start..offset).map_or(1, |s| s.chars().count() + 1);
        SourcePos { file: self.file.clone(), line: line as u32, column: column as u32 }
    }
}

struct Resolver<'a> {
    reader: &'a Reader<'a>,
    done: Vec<Option<Arc<Plugin>>>,
    in_progress: HashSet<usize>,
}

impl Resolver<'_> {
    /// The plugin index an id or alias names.
    fn lookup(&self, id: &str, position: &SourcePos, element: &str) -> Result<usize, MitsubaError> {
        let mut name = id;
        // Aliases may name aliases; each step names a distinct entry, so the chain is bounded by their number.
        for _ in 0..=self.reader.aliases.len() {
            if let Some(&index) = self.reader.ids.get(name) {
                return Ok(index);
            }
            match self.reader.aliases.get(name) {
                Some((target, _, _)) => name = target,
                None => break,
            }
        }
        Err(MitsubaError::at(position, element, format!("no plugin has the id \"{id}\"")))
    }

    /// The plugin `index` with its children resolved; `depth` counts the plugins being resolved around it.
    fn resolve(&mut self, index: usize, depth: usize) -> Result<Arc<Plugin>, MitsubaError> {
        if let Some(done) = &self.done[index] {
            return Ok(done.clone());
        }
        let raw = &self.reader.plugins[index];
        if depth > 2 * MAX_NESTING {
            return Err(MitsubaError::at(
                &raw.position,
                raw.element.clone(),
                format!("references chain plugins deeper than {} levels here", 2 * MAX_NESTING),
            ));
        }
        if !self.in_progress.insert(index) {
            return Err(MitsubaError::at(
                &raw.position,
                raw.element.clone(),
                "the plugin references itself through <ref>",
            ));
        }
        let mut children = Vec::with_capacity(raw.children.len());
        for child in &raw.children {
            let (target, reference) = match &child.target {
                Target::Inline(i) => (*i, None),
                Target::Reference { id, element } => (self.lookup(id, &child.position, element)?, Some(id.clone())),
            };
            if reference.is_some() && self.in_progress.contains(&target) {
                return Err(MitsubaError::at(
                    &child.position,
                    format!("<ref id=\"{}\">", reference.as_deref().unwrap_or_default()),
                    format!(
                        "a reference cycle: {} contains this reference to itself",
                        self.reader.plugins[target].element
                    ),
                ));
            }
            let plugin = self.resolve(target, depth + 1)?;
            children.push(Child { name: child.name.clone(), plugin, position: child.position.clone(), reference });
        }
        self.in_progress.remove(&index);
        let plugin = Arc::new(Plugin {
            category: raw.category,
            kind: raw.kind.clone(),
            id: raw.id.clone(),
            position: raw.position.clone(),
            params: raw.params.clone(),
            children,
        });
        self.done[index] = Some(plugin.clone());
        Ok(plugin)
    }
}

/// Replaces every `$name` in `text` by its parameter; a `$` not followed by a name is kept.
fn substitute(text: &str, variables: &HashMap<String, String>, used: &mut HashSet<String>) -> Result<String, String> {
    if !text.contains('$') {
        return Ok(text.to_string());
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find('$') {
        out.push_str(&rest[..at]);
        let after = &rest[at + 1..];
        let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
        if len == 0 {
            out.push('$');
        } else {
            let name = &after[..len];
            let value = variables.get(name).ok_or_else(|| {
                format!("the parameter `${name}` has no value: declare <default name=\"{name}\" value=\"...\"/> or define it")
            })?;
            out.push_str(value);
            used.insert(name.to_string());
        }
        rest = &after[len..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Reads a spectrum file as Mitsuba does: lines of "wavelength value", `#` comments.
fn read_spectrum_file(path: &Path, files: FileSource) -> Result<Spectrum, String> {
    let bytes = files.read(path).map_err(|e| format!("cannot read the spectrum file: {e}"))?;
    let text = std::str::from_utf8(&bytes).map_err(|_| format!("{} is not UTF-8 text", path.display()))?;
    let mut pairs = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        match fields[..] {
            [w, v] => pairs.push(format!("{w}:{v}")),
            _ => return Err(format!("{}:{}: expected \"wavelength value\"", path.display(), number + 1)),
        }
    }
    Spectrum::parse(&pairs.join(",")).map_err(|m| format!("{}: {m}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_agree_with_roxmltree_on_every_element() {
        let text = "<scene version=\"3.0.0\">\r\n\t<bsdf type=\"diffuse\"/><!-- é -->  <shape type=\"ü\">\n\n   <float name=\"x\" value=\"1\"/></shape>\n</scene>";
        let document = roxmltree::Document::parse(text).unwrap();
        let line_starts = std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect();
        let source = Source { file: Arc::new(PathBuf::from("s.xml")), text, line_starts };
        for node in document.descendants().filter(roxmltree::Node::is_element) {
            let expected = document.text_pos_at(node.range().start);
            let ours = source.position(node.range().start);
            assert_eq!((ours.line, ours.column), (expected.row, expected.col), "{:?}", node.tag_name());
        }
    }

    #[test]
    fn substitution_replaces_every_name_and_keeps_a_lone_dollar() {
        let vars: HashMap<String, String> =
            [("a".to_string(), "1".to_string()), ("ab".to_string(), "2".to_string())].into();
        let mut used = HashSet::new();
        assert!(substitute("$a_", &vars, &mut used).unwrap_err().contains("`$a_`"));
        assert_eq!(substitute("$a$ab x$ y", &vars, &mut used).unwrap(), "12 x$ y");
        assert_eq!(used.len(), 2);
        assert!(substitute("$missing", &vars, &mut used).unwrap_err().contains("$missing"));
    }
}
