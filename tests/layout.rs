//! The workspace's layout rules (issue 18), checked on the sources:
//!
//! * no import cycle between modules, in any crate of the workspace: a
//!   module never uses an item of a module that (directly or through
//!   others) uses one of its own items;
//! * no hand-written source file over [`MAX_LINES`] lines (the emitted
//!   crate aside), and no emitted source file over [`MAX_EMITTED_BYTES`]
//!   (the emitted crate is data in table files and a thin binding);
//! * crate dependencies point one way (CLI -> simulation -> runtime ->
//!   generated -> solver), development dependencies included, and the
//!   simulation library has no command line or plotting dependency.
//!
//! Module edges come from parsing every file with syn: each `use` tree and
//! each path that starts at `crate`, `self`, `super` or a child module is
//! resolved, through re-exports, to the module that defines the item.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

/// Longest hand-written source file, lines ("about 800" in issue 18).
const MAX_LINES: usize = 800;

/// Largest emitted Rust source file, bytes (issue 25: tables live in the
/// table files, not in source).
const MAX_EMITTED_BYTES: u64 = 100_000;

/// Directories (relative to the workspace root) whose files are emitted,
/// not hand-written, or are not Rust sources of the project.
const NOT_HAND_WRITTEN: &[&str] = &["generated/", "target/", "fuzz/target/"];

#[test]
fn emitted_sources_are_small() {
    let dir = workspace_root().join("generated/src");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let bytes = std::fs::metadata(&path).unwrap().len();
        assert!(
            bytes <= MAX_EMITTED_BYTES,
            "{}: {bytes} bytes of emitted source (at most {MAX_EMITTED_BYTES})",
            path.display()
        );
        seen += 1;
    }
    assert!(seen >= 4, "only {seen} emitted files");
}

fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file of the project, relative to the workspace root.
fn rust_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, root: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let rel = path.strip_prefix(root).unwrap().to_path_buf();
            let name = rel.to_string_lossy();
            if name.starts_with('.') || name == "target" || name.ends_with("/target") {
                continue;
            }
            if path.is_dir() {
                walk(&path, root, out);
            } else if name.ends_with(".rs") {
                out.push(rel);
            }
        }
    }
    let root = workspace_root();
    let mut files = Vec::new();
    walk(&root, &root, &mut files);
    files.sort();
    files
}

fn is_hand_written(rel: &Path) -> bool {
    let name = rel.to_string_lossy();
    !NOT_HAND_WRITTEN
        .iter()
        .any(|prefix| name.starts_with(prefix))
}

#[test]
fn no_hand_written_source_file_is_over_the_limit() {
    let mut too_long = Vec::new();
    let mut checked = 0;
    for rel in rust_files().iter().filter(|rel| is_hand_written(rel)) {
        let text = std::fs::read_to_string(workspace_root().join(rel)).unwrap();
        checked += 1;
        let lines = text.lines().count();
        if lines > MAX_LINES {
            too_long.push(format!("{} ({lines} lines)", rel.display()));
        }
    }
    assert!(checked > 50, "only {checked} source files found");
    assert!(
        too_long.is_empty(),
        "hand-written files over {MAX_LINES} lines: {}",
        too_long.join(", ")
    );
}

// ---------------------------------------------------------------------------
// Module graph

/// A module: its path from the crate root (`[]` is the root).
type ModPath = Vec<String>;

#[derive(Default)]
struct Module {
    /// The file that holds the module's items (inline modules: the parent's).
    file: PathBuf,
    children: BTreeSet<String>,
    /// Names bound by `use` items: name -> the path it stands for, already
    /// made absolute (first segment `crate`) when it starts inside the crate.
    bindings: BTreeMap<String, Vec<String>>,
    /// Paths of `use` globs (`use super::*`), absolute.
    globs: Vec<Vec<String>>,
    /// Names of the items the module defines (functions, types, traits,
    /// constants, statics, macros).
    defines: BTreeSet<String>,
    /// Every path the module's items mention.
    references: Vec<Vec<String>>,
}

/// One crate's module tree, read from its root file.
struct Crate {
    root_file: PathBuf,
    modules: BTreeMap<ModPath, Module>,
}

fn path_segments(path: &syn::Path) -> Vec<String> {
    path.segments.iter().map(|s| s.ident.to_string()).collect()
}

/// Every complete path of a use tree, with the name it binds (`None` for a
/// glob): `use a::{b, c as d, e::*}` gives `a::b` as b, `a::c` as d, `a::e`
/// as glob.
fn use_paths(
    tree: &syn::UseTree,
    prefix: &mut Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>)>,
) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            use_paths(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let name = n.ident.to_string();
            if name == "self" {
                out.push((prefix.clone(), prefix.last().cloned()));
            } else {
                let mut full = prefix.clone();
                full.push(name.clone());
                out.push((full, Some(name)));
            }
        }
        syn::UseTree::Rename(r) => {
            let mut full = prefix.clone();
            full.push(r.ident.to_string());
            out.push((full, Some(r.rename.to_string())));
        }
        syn::UseTree::Glob(_) => out.push((prefix.clone(), None)),
        syn::UseTree::Group(g) => {
            for item in &g.items {
                use_paths(item, prefix, out);
            }
        }
    }
}

/// Collects the paths of one module's own items (child modules excluded).
struct PathCollector {
    uses: Vec<(Vec<String>, Option<String>)>,
    paths: Vec<Vec<String>>,
}

impl<'ast> Visit<'ast> for PathCollector {
    fn visit_item_mod(&mut self, _: &'ast syn::ItemMod) {
        // A child module is a node of its own.
    }
    fn visit_item_use(&mut self, item: &'ast syn::ItemUse) {
        use_paths(&item.tree, &mut Vec::new(), &mut self.uses);
    }
    fn visit_visibility(&mut self, _: &'ast syn::Visibility) {
        // `pub(super)` names where an item is seen from, not what it uses.
    }
    fn visit_path(&mut self, path: &'ast syn::Path) {
        self.paths.push(path_segments(path));
        syn::visit::visit_path(self, path);
    }
}

/// `#[path = "..."]` of a module item, if any.
fn path_attribute(item: &syn::ItemMod) -> Option<String> {
    item.attrs.iter().find_map(|attr| {
        let syn::Meta::NameValue(nv) = &attr.meta else {
            return None;
        };
        if !nv.path.is_ident("path") {
            return None;
        }
        match &nv.value {
            syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) => Some(s.value()),
            _ => None,
        }
    })
}

impl Crate {
    fn read(root_file: &Path) -> Crate {
        let mut krate = Crate {
            root_file: root_file.to_path_buf(),
            modules: BTreeMap::new(),
        };
        let dir = workspace_root()
            .join(root_file)
            .parent()
            .unwrap()
            .to_path_buf();
        let file = parse(&workspace_root().join(root_file));
        krate.add_module(Vec::new(), root_file.to_path_buf(), &file.items, dir);
        krate
    }

    /// Adds the module at `path` with `items`; `child_dir` is where its
    /// out-of-line children live.
    fn add_module(
        &mut self,
        path: ModPath,
        file: PathBuf,
        items: &[syn::Item],
        child_dir: PathBuf,
    ) {
        let mut collector = PathCollector {
            uses: Vec::new(),
            paths: Vec::new(),
        };
        for item in items {
            collector.visit_item(item);
        }
        let mut module = Module {
            file: file.clone(),
            ..Module::default()
        };
        for item in items {
            if let syn::Item::Mod(m) = item {
                module.children.insert(m.ident.to_string());
            }
            if let Some(name) = defined_name(item) {
                module.defines.insert(name);
            }
        }
        let absolute =
            |p: &[String]| -> Vec<String> { absolute_path(&path, &module_children(items), p) };
        for (use_path, name) in &collector.uses {
            let full = absolute(use_path);
            match name {
                Some(name) if name != "_" => {
                    module.bindings.insert(name.clone(), full.clone());
                }
                Some(_) => {}
                None => module.globs.push(full.clone()),
            }
            module.references.push(full);
        }
        for p in &collector.paths {
            module.references.push(absolute(p));
        }
        self.modules.insert(path.clone(), module);

        for item in items {
            let syn::Item::Mod(m) = item else { continue };
            let name = m.ident.to_string();
            let mut child = path.clone();
            child.push(name.clone());
            if let Some((_, content)) = &m.content {
                self.add_module(child, file.clone(), content, child_dir.join(&name));
                continue;
            }
            let root = workspace_root();
            let (child_file, grandchild_dir) = if let Some(p) = path_attribute(m) {
                let f = root.join(&file).parent().unwrap().join(p);
                let d = f.parent().unwrap().join(f.file_stem().unwrap());
                (f, d)
            } else if child_dir.join(format!("{name}.rs")).is_file() {
                (child_dir.join(format!("{name}.rs")), child_dir.join(&name))
            } else {
                (child_dir.join(&name).join("mod.rs"), child_dir.join(&name))
            };
            let parsed = parse(&child_file);
            let rel = child_file
                .strip_prefix(&root)
                .unwrap_or(&child_file)
                .to_path_buf();
            self.add_module(child, rel, &parsed.items, grandchild_dir);
        }
    }

    /// The module that defines what `path` (absolute, `crate::...`) names,
    /// following modules and `use` bindings; `None` outside the crate.
    fn resolve(&self, path: &[String], depth: usize) -> Option<ModPath> {
        if depth > 16 || path.first().map(String::as_str) != Some("crate") {
            return None;
        }
        let mut at: ModPath = Vec::new();
        for (i, segment) in path.iter().enumerate().skip(1) {
            let module = self.modules.get(&at)?;
            if module.children.contains(segment) {
                at.push(segment.clone());
                continue;
            }
            let rest = &path[i + 1..];
            if module.defines.contains(segment) {
                return Some(at);
            }
            if let Some(bound) = module.bindings.get(segment) {
                // A name bound to something outside the crate is no edge.
                let mut through = bound.clone();
                through.extend_from_slice(rest);
                return self.resolve(&through, depth + 1);
            }
            // A glob re-export (`pub use settings::*`): the first glob
            // module that defines or binds the name.
            for glob in &module.globs {
                let Some(base) = self.resolve(glob, depth + 1) else {
                    continue;
                };
                let Some(inner) = self.modules.get(&base) else {
                    continue;
                };
                if inner.defines.contains(segment)
                    || inner.bindings.contains_key(segment)
                    || inner.children.contains(segment)
                {
                    let mut through = vec!["crate".to_string()];
                    through.extend(base.iter().cloned());
                    through.push(segment.clone());
                    through.extend_from_slice(rest);
                    return self.resolve(&through, depth + 1);
                }
            }
            // Unknown (a variant, a field, a macro-made item): the module.
            return Some(at);
        }
        Some(at)
    }

    /// Module -> modules it uses, with a witness (file and path) per edge.
    fn edges(&self) -> BTreeMap<ModPath, BTreeMap<ModPath, String>> {
        let mut edges: BTreeMap<ModPath, BTreeMap<ModPath, String>> = BTreeMap::new();
        for (from, module) in &self.modules {
            let entry = edges.entry(from.clone()).or_default();
            for reference in &module.references {
                let Some(to) = self.resolve(reference, 0) else {
                    continue;
                };
                // A module naming its own items, or its ancestors only as a
                // way down to something else, is not a dependency.
                if &to == from {
                    continue;
                }
                entry.entry(to).or_insert_with(|| {
                    format!("{} `{}`", module.file.display(), reference.join("::"))
                });
            }
        }
        edges
    }
}

/// The name an item defines in its module's namespace, if any.
fn defined_name(item: &syn::Item) -> Option<String> {
    let ident = match item {
        syn::Item::Const(i) => &i.ident,
        syn::Item::Enum(i) => &i.ident,
        syn::Item::Fn(i) => &i.sig.ident,
        syn::Item::Static(i) => &i.ident,
        syn::Item::Struct(i) => &i.ident,
        syn::Item::Trait(i) => &i.ident,
        syn::Item::TraitAlias(i) => &i.ident,
        syn::Item::Type(i) => &i.ident,
        syn::Item::Union(i) => &i.ident,
        syn::Item::Macro(i) => i.ident.as_ref()?,
        _ => return None,
    };
    Some(ident.to_string())
}

fn module_children(items: &[syn::Item]) -> BTreeSet<String> {
    items
        .iter()
        .filter_map(|item| match item {
            syn::Item::Mod(m) => Some(m.ident.to_string()),
            _ => None,
        })
        .collect()
}

/// Makes a path written in module `at` absolute (`crate::...`) when it
/// starts inside the crate: `crate`, `self`, `super` or a child module.
/// Other paths (std, other crates, local items) are returned unchanged.
fn absolute_path(at: &[String], children: &BTreeSet<String>, path: &[String]) -> Vec<String> {
    let Some(first) = path.first() else {
        return path.to_vec();
    };
    let mut base: Vec<String> = at.to_vec();
    let mut rest = path;
    match first.as_str() {
        "crate" => {
            base.clear();
            rest = &path[1..];
        }
        "self" => rest = &path[1..],
        "super" => {
            while rest.first().map(String::as_str) == Some("super") {
                base.pop();
                rest = &rest[1..];
            }
        }
        name if children.contains(name) => {}
        _ => return path.to_vec(),
    }
    let mut full = vec!["crate".to_string()];
    full.extend(base);
    full.extend_from_slice(rest);
    full
}

fn parse(file: &Path) -> syn::File {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()))
}

/// Strongly connected components with more than one module (Tarjan).
fn cycles(edges: &BTreeMap<ModPath, BTreeMap<ModPath, String>>) -> Vec<Vec<ModPath>> {
    struct Tarjan<'a> {
        edges: &'a BTreeMap<ModPath, BTreeMap<ModPath, String>>,
        index: BTreeMap<ModPath, usize>,
        low: BTreeMap<ModPath, usize>,
        stack: Vec<ModPath>,
        on_stack: BTreeSet<ModPath>,
        found: Vec<Vec<ModPath>>,
    }
    impl Tarjan<'_> {
        fn visit(&mut self, v: &ModPath) {
            let n = self.index.len();
            self.index.insert(v.clone(), n);
            self.low.insert(v.clone(), n);
            self.stack.push(v.clone());
            self.on_stack.insert(v.clone());
            let next: Vec<ModPath> = self
                .edges
                .get(v)
                .map(|e| e.keys().cloned().collect())
                .unwrap_or_default();
            for w in &next {
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let low = self.low[v].min(self.low[w]);
                    self.low.insert(v.clone(), low);
                } else if self.on_stack.contains(w) {
                    let low = self.low[v].min(self.index[w]);
                    self.low.insert(v.clone(), low);
                }
            }
            if self.low[v] == self.index[v] {
                let mut component = Vec::new();
                loop {
                    let w = self.stack.pop().unwrap();
                    self.on_stack.remove(&w);
                    let done = &w == v;
                    component.push(w);
                    if done {
                        break;
                    }
                }
                if component.len() > 1 {
                    self.found.push(component);
                }
            }
        }
    }
    let mut t = Tarjan {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        found: Vec::new(),
    };
    for v in edges.keys() {
        if !t.index.contains_key(v) {
            t.visit(v);
        }
    }
    t.found
}

fn show(path: &ModPath) -> String {
    if path.is_empty() {
        "crate".to_string()
    } else {
        format!("crate::{}", path.join("::"))
    }
}

/// Every crate root of the project: libraries, binaries, tests, examples,
/// benches and fuzz targets (emitted code included: it must not cycle either).
fn crate_roots() -> Vec<PathBuf> {
    let files = rust_files();
    let mut roots = Vec::new();
    for rel in &files {
        let parts: Vec<String> = rel
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect();
        let n = parts.len();
        let file = parts[n - 1].as_str();
        let parent = if n >= 2 { parts[n - 2].as_str() } else { "" };
        let is_root = matches!((parent, file), ("src", "lib.rs") | ("src", "main.rs"))
            || (n >= 2
                && matches!(
                    parent,
                    "tests" | "examples" | "benches" | "fuzz_targets" | "bin"
                ))
            || (n >= 3 && parts[n - 3] == "examples" && file == "main.rs");
        // Shared helper files under tests/ are modules of a test, not roots.
        if is_root {
            roots.push(rel.clone());
        }
    }
    roots
}

#[test]
fn no_module_imports_from_a_module_that_imports_from_it() {
    let roots = crate_roots();
    for expected in [
        "src/lib.rs",
        "sim/src/lib.rs",
        "runtime/src/lib.rs",
        "generator/src/lib.rs",
        "capi/src/lib.rs",
    ] {
        assert!(
            roots.iter().any(|r| r == Path::new(expected)),
            "crate root {expected} not found"
        );
    }
    let mut report = Vec::new();
    let mut modules = 0;
    let mut edge_count = 0;
    for root in &roots {
        let krate = Crate::read(root);
        modules += krate.modules.len();
        let edges = krate.edges();
        edge_count += edges.values().map(BTreeMap::len).sum::<usize>();
        for component in cycles(&edges) {
            let members: BTreeSet<&ModPath> = component.iter().collect();
            let mut witnesses = Vec::new();
            for from in &component {
                for (to, witness) in &edges[from] {
                    if members.contains(to) {
                        witnesses.push(format!("    {} -> {}: {witness}", show(from), show(to)));
                    }
                }
            }
            report.push(format!(
                "{}: cycle between {}\n{}",
                krate.root_file.display(),
                component.iter().map(show).collect::<Vec<_>>().join(", "),
                witnesses.join("\n")
            ));
        }
    }
    println!(
        "{} crate roots, {modules} modules, {edge_count} module edges",
        roots.len()
    );
    assert!(
        edge_count > 100,
        "only {edge_count} module edges found: the parser missed the imports"
    );
    assert!(report.is_empty(), "import cycles:\n{}", report.join("\n"));
}

/// The checker itself: a cycle through a re-export is found, a tree is not.
#[test]
fn the_cycle_check_finds_a_cycle_through_a_re_export() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::write(
        root.join("lib.rs"),
        "mod a;\nmod b;\npub use a::Thing;\npub struct Root;\n",
    )
    .unwrap();
    std::fs::write(root.join("a.rs"), "pub struct Thing(crate::b::Other);\n").unwrap();
    std::fs::write(root.join("b.rs"), "pub struct Other(crate::Thing);\n").unwrap();
    let krate = Crate::read(&root.join("lib.rs"));
    let edges = krate.edges();
    let a = vec!["a".to_string()];
    let b = vec!["b".to_string()];
    assert!(
        edges[&b].contains_key(&a),
        "crate::Thing must resolve through the re-export to a"
    );
    let found = cycles(&edges);
    assert_eq!(found.len(), 1);
    assert_eq!(
        found[0].iter().collect::<BTreeSet<_>>(),
        [&a, &b].into_iter().collect()
    );

    std::fs::write(root.join("b.rs"), "pub struct Other(pub u8);\n").unwrap();
    let krate = Crate::read(&root.join("lib.rs"));
    assert!(cycles(&krate.edges()).is_empty());
    // Through a glob re-export: `b` uses `crate::Thing`, which the root
    // re-exports from `a` with a glob, and `a` uses `b`.
    std::fs::write(root.join("lib.rs"), "mod a;\nmod b;\npub use a::*;\n").unwrap();
    std::fs::write(root.join("b.rs"), "pub struct Other(crate::Thing);\n").unwrap();
    let krate = Crate::read(&root.join("lib.rs"));
    let edges = krate.edges();
    assert!(
        edges[&b].contains_key(&a),
        "the glob re-export must resolve to a"
    );
    assert_eq!(cycles(&edges).len(), 1);
    std::fs::write(
        root.join("lib.rs"),
        "mod a;\nmod b;\npub use a::Thing;\npub struct Root;\n",
    )
    .unwrap();
    std::fs::write(root.join("b.rs"), "pub struct Other(pub u8);\n").unwrap();
    // A child's `use super::*` test module alone is no cycle.
    std::fs::write(
        root.join("b.rs"),
        "pub struct Other(pub u8);\nmod tests { use super::*; }\n",
    )
    .unwrap();
    let krate = Crate::read(&root.join("lib.rs"));
    assert!(cycles(&krate.edges()).is_empty());
}

// ---------------------------------------------------------------------------
// Crate dependencies

/// The project's crates from bottom to top: a crate may depend (normal,
/// build or dev) only on crates strictly below it.
const CRATE_LAYERS: &[(&str, &str, u8)] = &[
    ("solver/Cargo.toml", "capsule-mpc-solver", 0),
    ("pulseq/Cargo.toml", "capsule-mpc-pulseq", 0),
    ("generated/Cargo.toml", "capsule-mpc-generated", 1),
    ("generator/Cargo.toml", "capsule-mpc-generator", 1),
    ("runtime/Cargo.toml", "capsule-mpc-runtime", 2),
    ("capi/Cargo.toml", "capsule-mpc-capi", 3),
    ("sim/Cargo.toml", "capsule-mpc-sim", 3),
    ("calibrate/Cargo.toml", "capsule-mpc-calibrate", 4),
    ("Cargo.toml", "capsule-mpc", 5),
    ("fuzz/Cargo.toml", "capsule-mpc-fuzz", 6),
];

fn dependency_names(manifest: &toml::Value) -> Vec<(String, String)> {
    let mut names = Vec::new();
    for table in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if let Some(deps) = manifest.get(table).and_then(|t| t.as_table()) {
            for name in deps.keys() {
                names.push((table.to_string(), name.clone()));
            }
        }
    }
    names
}

#[test]
fn crate_dependencies_point_one_way() {
    let layer_of: BTreeMap<&str, u8> = CRATE_LAYERS
        .iter()
        .map(|(_, name, layer)| (*name, *layer))
        .collect();
    for (manifest_path, name, layer) in CRATE_LAYERS {
        let text = std::fs::read_to_string(workspace_root().join(manifest_path)).unwrap();
        let manifest: toml::Value = toml::from_str(&text).unwrap();
        let package = manifest["package"]["name"].as_str().unwrap();
        assert_eq!(package, *name, "{manifest_path}");
        for (table, dep) in dependency_names(&manifest) {
            if let Some(dep_layer) = layer_of.get(dep.as_str()) {
                assert!(
                    dep_layer < layer,
                    "{name} ({manifest_path} [{table}]) depends on {dep}, which is not below it"
                );
            } else {
                assert!(
                    !dep.starts_with("capsule-mpc"),
                    "{manifest_path}: unknown project crate {dep}"
                );
            }
        }
    }
    // Every workspace member is placed in a layer.
    let root: toml::Value =
        toml::from_str(&std::fs::read_to_string(workspace_root().join("Cargo.toml")).unwrap())
            .unwrap();
    for member in root["workspace"]["members"].as_array().unwrap() {
        let manifest = format!("{}/Cargo.toml", member.as_str().unwrap());
        assert!(
            CRATE_LAYERS.iter().any(|(m, _, _)| *m == manifest),
            "{manifest} has no layer"
        );
    }
    // The simulation library is usable without the command line or plots.
    let sim: toml::Value =
        toml::from_str(&std::fs::read_to_string(workspace_root().join("sim/Cargo.toml")).unwrap())
            .unwrap();
    for (table, dep) in dependency_names(&sim) {
        assert!(
            !["clap", "plotters", "indicatif", "capsule-mpc"].contains(&dep.as_str()),
            "sim [{table}] depends on {dep}"
        );
    }
}
