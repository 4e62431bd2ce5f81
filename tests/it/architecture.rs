//! The architecture, as the compiler and these tests keep it.
//!
//! **Crates by layer.** The library is one crate per layer under `src/` (core, runtime,
//! recording, drivers, distributed, and the `ratelab` facade at `src/lib.rs`), the lab in
//! `lab/`. Each depends only on the layers below it ([`LAYERS`]), and the core on none of
//! the crates that talk to the world (Zenoh, rerun, PyO3, candle, tract, MuJoCo) — as
//! `cargo tree` resolves it, not only as its manifest says.
//!
//! **No import cycle in a crate.** No module imports one that imports it back, directly or
//! through others (issue "Your own node": facts with no home made two import cycles; they
//! now live in leaves — `plant`, `ids`, `time`, `qos`, `runlog`). Across crates Cargo
//! forbids cycles already.
//!
//! Each crate's `*.rs` is parsed with `syn`; a module depends on another when its code (not
//! its doc comments, not its `#[cfg(test)]` items) names a path into it: `use crate::a::b`,
//! `crate::a::f()`, `super::x`, also inside macro calls. A path names the deepest module it
//! reaches (`crate::graph::spec::GraphSpec` → `graph::spec`); a module does not depend on
//! its own submodules by declaring them.

use proc_macro2::{TokenStream, TokenTree};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use syn::visit::Visit;

/// Module path (`graph::spec`; the crate root is `crate`) → the modules it names.
type Deps = BTreeMap<String, BTreeSet<String>>;
/// For each dependency between siblings, one between modules it stands for
/// ([`between_siblings`]).
type Because = BTreeMap<(String, String), (String, String)>;

/// Every module of `src` by its path, with its parsed file.
fn modules(src: &Path) -> BTreeMap<String, syn::File> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("read src") {
            let path = entry.expect("dir entry").path();
            if path.is_dir() {
                // A folder with a manifest is a crate of its own.
                if !path.join("Cargo.toml").exists() {
                    stack.push(path);
                }
                continue;
            }
            if path.extension().is_none_or(|e| e != "rs") {
                continue;
            }
            let rel = path.strip_prefix(src).unwrap().with_extension("");
            let mut parts: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if parts.last().is_some_and(|p| p == "mod") {
                parts.pop();
            }
            let name = if parts == ["lib"] {
                "crate".to_string()
            } else {
                parts.join("::")
            };
            let text = std::fs::read_to_string(&path).expect("read module");
            let file = syn::parse_file(&text)
                .unwrap_or_else(|e| panic!("{} does not parse: {e}", path.display()));
            out.insert(name, file);
        }
    }
    out
}

fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.parse_args::<syn::Meta>()
                .is_ok_and(|m| m.path().is_ident("test"))
    })
}

/// The paths one module's code names, each as segments from the crate root.
struct Names {
    /// Where the code being read is, as segments (empty for the crate root): the file's
    /// module, then any inline `mod x { … }` it is inside.
    module: Vec<String>,
    found: Vec<Vec<String>>,
}

impl Names {
    /// `segments` as written (`crate::…`, `super::…`, `self::…`), from the crate root;
    /// `None` for a path into another crate or a local name.
    fn absolute(&self, segments: &[String]) -> Option<Vec<String>> {
        let (first, rest) = segments.split_first()?;
        match first.as_str() {
            "crate" => Some(rest.to_vec()),
            "self" => Some([self.module.as_slice(), rest].concat()),
            "super" => {
                let mut base = self.module.to_vec();
                base.pop()?;
                let mut rest = rest;
                while rest.first().is_some_and(|s| s == "super") {
                    base.pop()?;
                    rest = &rest[1..];
                }
                Some([base.as_slice(), rest].concat())
            }
            _ => None,
        }
    }

    fn add(&mut self, segments: &[String]) {
        if let Some(p) = self.absolute(segments) {
            self.found.push(p);
        }
    }

    /// `crate :: a :: b` (or `super`, `self`) sequences in a macro call's tokens.
    fn scan_tokens(&mut self, tokens: TokenStream) {
        let mut path: Vec<String> = Vec::new();
        let mut colons = 0;
        for tt in tokens {
            match tt {
                TokenTree::Group(g) => {
                    self.flush(&mut path);
                    self.scan_tokens(g.stream());
                }
                TokenTree::Ident(i) => {
                    let s = i.to_string();
                    if path.is_empty() || colons != 2 {
                        self.flush(&mut path);
                    }
                    if path.is_empty() && !matches!(s.as_str(), "crate" | "super" | "self") {
                        continue;
                    }
                    path.push(s);
                    colons = 0;
                }
                TokenTree::Punct(p) if p.as_char() == ':' && !path.is_empty() => colons += 1,
                TokenTree::Punct(_) | TokenTree::Literal(_) => self.flush(&mut path),
            }
        }
        self.flush(&mut path);
    }

    fn flush(&mut self, path: &mut Vec<String>) {
        if path.len() > 1 {
            self.add(path);
        }
        path.clear();
    }

    fn use_tree(&mut self, prefix: &mut Vec<String>, tree: &syn::UseTree) {
        match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            syn::UseTree::Name(n) => {
                prefix.push(n.ident.to_string());
                self.add(prefix);
                prefix.pop();
            }
            syn::UseTree::Rename(r) => {
                prefix.push(r.ident.to_string());
                self.add(prefix);
                prefix.pop();
            }
            syn::UseTree::Glob(_) => self.add(prefix),
            syn::UseTree::Group(g) => {
                for t in &g.items {
                    self.use_tree(prefix, t);
                }
            }
        }
    }
}

/// An item's attributes (none for the kinds that cannot be `#[cfg(test)]` here).
fn attrs(item: &syn::Item) -> &[syn::Attribute] {
    use syn::Item::*;
    match item {
        Const(i) => &i.attrs,
        Enum(i) => &i.attrs,
        Fn(i) => &i.attrs,
        Impl(i) => &i.attrs,
        Macro(i) => &i.attrs,
        Mod(i) => &i.attrs,
        Static(i) => &i.attrs,
        Struct(i) => &i.attrs,
        Trait(i) => &i.attrs,
        Type(i) => &i.attrs,
        Union(i) => &i.attrs,
        Use(i) => &i.attrs,
        _ => &[],
    }
}

impl<'ast> Visit<'ast> for Names {
    fn visit_item(&mut self, item: &'ast syn::Item) {
        if !is_cfg_test(attrs(item)) {
            syn::visit::visit_item(self, item);
        }
    }

    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        self.module.push(m.ident.to_string());
        syn::visit::visit_item_mod(self, m);
        self.module.pop();
    }

    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        self.use_tree(&mut Vec::new(), &u.tree);
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segments: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        self.add(&segments);
        syn::visit::visit_path(self, p);
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        self.scan_tokens(m.tokens.clone());
        syn::visit::visit_macro(self, m);
    }
}

/// A module's name as its path's segments (`tui::view` → `["tui", "view"]`; the crate's
/// root, `crate`, → none).
fn module_path(name: &str) -> Vec<String> {
    if name == "crate" {
        Vec::new()
    } else {
        name.split("::").map(str::to_string).collect()
    }
}

/// Which module each module's code depends on (itself, its ancestors' declarations of it
/// and its own submodules left out).
fn dependencies(src: &Path) -> Deps {
    let mods = modules(src);
    let known: BTreeSet<String> = mods.keys().cloned().collect();
    let mut deps = Deps::new();
    for (name, file) in &mods {
        let mut names = Names {
            module: module_path(name),
            found: Vec::new(),
        };
        names.visit_file(file);
        let mut to = BTreeSet::new();
        for path in names.found {
            // The deepest module the path reaches.
            let target = (1..=path.len())
                .rev()
                .map(|n| path[..n].join("::"))
                .find(|m| known.contains(m));
            if let Some(t) = target {
                let own_child = t.starts_with(&format!("{name}::")) || name == "crate";
                if &t != name && !own_child {
                    to.insert(t);
                }
            }
        }
        deps.insert(name.clone(), to);
    }
    deps
}

/// A cycle of `deps` (its modules in order, the first repeated at the end), if any.
fn find_cycle(deps: &Deps) -> Option<Vec<String>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        Open,
        Done,
    }
    fn walk(
        m: &str,
        deps: &Deps,
        marks: &mut BTreeMap<String, Mark>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        match marks.get(m) {
            Some(Mark::Done) => return None,
            Some(Mark::Open) => {
                let at = path.iter().position(|p| p == m).unwrap();
                let mut cycle = path[at..].to_vec();
                cycle.push(m.to_string());
                return Some(cycle);
            }
            None => {}
        }
        marks.insert(m.to_string(), Mark::Open);
        path.push(m.to_string());
        for d in deps.get(m).into_iter().flatten() {
            if let Some(c) = walk(d, deps, marks, path) {
                return Some(c);
            }
        }
        path.pop();
        marks.insert(m.to_string(), Mark::Done);
        None
    }
    let mut marks = BTreeMap::new();
    deps.keys()
        .find_map(|m| walk(m, deps, &mut marks, &mut Vec::new()))
}

/// `deps` seen between siblings: a module's dependency on another becomes one between the
/// two children of their deepest common ancestor that hold them (`tui::view::graph` →
/// `tui::navigate` is `tui::view` → `tui::navigate`), so that a parent that uses its child is
/// counted with it. A dependency between a module and its own ancestor or descendant is
/// containment (a child's `super::`, a parent's re-export), not an edge. A cycle among the
/// siblings is then a circle in the code: each sibling, its children included, needs the
/// next. Also returned: for each edge between siblings, one dependency it stands for.
fn between_siblings(deps: &Deps) -> (Deps, Because) {
    let (mut lifted, mut because) = (Deps::new(), BTreeMap::new());
    for (a, bs) in deps {
        let pa = module_path(a);
        for b in bs {
            let pb = module_path(b);
            let common = pa.iter().zip(&pb).take_while(|(x, y)| x == y).count();
            if common == pa.len() || common == pb.len() {
                continue;
            }
            let (sa, sb) = (pa[..=common].join("::"), pb[..=common].join("::"));
            because
                .entry((sa.clone(), sb.clone()))
                .or_insert_with(|| (a.clone(), b.clone()));
            lifted.entry(sa).or_default().insert(sb);
        }
    }
    (lifted, because)
}

/// The library's crates, lowest layer first: (package, folder, the workspace's packages it
/// may depend on).
const LAYERS: &[(&str, &str, &[&str])] = &[
    ("ratelab-core", "src/core", &[]),
    ("ratelab-runtime", "src/runtime", &["ratelab-core"]),
    (
        "ratelab-python",
        "src/python",
        &["ratelab-core", "ratelab-runtime"],
    ),
    (
        "ratelab-ros2",
        "src/ros2",
        &["ratelab-core", "ratelab-runtime"],
    ),
    (
        "ratelab-recording",
        "src/recording",
        &["ratelab-core", "ratelab-runtime"],
    ),
    (
        "ratelab-drivers",
        "src/drivers",
        &[
            "ratelab-core",
            "ratelab-runtime",
            "ratelab-ros2",
            "ratelab-recording",
        ],
    ),
    // Beside the recordings, the ROS 2 layer and the lab's sessions, not above them:
    // touching one rebuilds neither the graph across processes nor the others.
    (
        "ratelab-distributed",
        "src/distributed",
        &["ratelab-core", "ratelab-runtime"],
    ),
    // The exercises measure through the drivers and launches across processes; the facade
    // does not hold them (issue "One front-end kit…", items 5 and 6).
    (
        "ratelab-exercises",
        "src/exercises",
        &[
            "ratelab-core",
            "ratelab-runtime",
            "ratelab-ros2",
            "ratelab-drivers",
            "ratelab-distributed",
        ],
    ),
    (
        "ratelab",
        "src",
        &[
            "ratelab-core",
            "ratelab-runtime",
            "ratelab-python",
            "ratelab-ros2",
            "ratelab-recording",
            "ratelab-drivers",
            "ratelab-distributed",
        ],
    ),
    ("ratelab-lab", "lab", &["ratelab", "ratelab-exercises"]),
    // The Python API, over the library: a front end beside the command line, not above it.
    ("ratelab-py", "src/py", &["ratelab", "ratelab-exercises"]),
    // The wheel's extension module: the Python API and the `ratelab` command it installs.
    (
        "ratelab-wheel",
        "src/wheel",
        &["ratelab", "ratelab-py", "ratelab-lab"],
    ),
];

/// The packages a crate's manifest names under `[dependencies]` (its normal dependencies);
/// the facade's manifest is the workspace's, at the top.
fn manifest_dependencies(dir: &str) -> BTreeSet<String> {
    let dir = if dir == "src" { "" } else { dir };
    let text = std::fs::read_to_string(crate::repo(dir).join("Cargo.toml")).unwrap();
    let manifest: toml::Table = toml::from_str(&text).unwrap();
    manifest
        .get("dependencies")
        .and_then(|d| d.as_table())
        .map(|d| d.keys().cloned().collect())
        .unwrap_or_default()
}

/// Every package `package` is built with (its normal dependencies, transitively), as
/// `cargo tree` resolves them.
fn resolved_dependencies(package: &str) -> BTreeSet<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .current_dir(crate::repo(""))
        .args([
            "tree",
            "--locked",
            "--offline",
            "-e",
            "normal",
            "--prefix",
            "none",
        ])
        .args(["--format", "{p}", "-p", package])
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

#[test]
fn each_crate_depends_only_on_the_layers_below_it() {
    let all: BTreeSet<&str> = LAYERS.iter().map(|(p, ..)| *p).collect();
    for (package, dir, allowed) in LAYERS {
        let ours: BTreeSet<String> = manifest_dependencies(dir)
            .into_iter()
            .filter(|d| all.contains(d.as_str()))
            .collect();
        let allowed: BTreeSet<String> = allowed.iter().map(|s| s.to_string()).collect();
        assert!(
            ours.is_subset(&allowed),
            "{package} depends on {:?}, above its layer",
            ours.difference(&allowed).collect::<Vec<_>>()
        );
    }
    // Every crate of the workspace is in LAYERS.
    let text = std::fs::read_to_string(crate::repo("Cargo.toml")).unwrap();
    let root: toml::Table = toml::from_str(&text).unwrap();
    let members: BTreeSet<&str> = root["workspace"]["members"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|m| m.as_str())
        .collect();
    let dirs: BTreeSet<&str> = LAYERS
        .iter()
        .map(|(_, d, _)| if *d == "src" { "." } else { *d })
        .collect();
    assert_eq!(members, dirs);
}

#[test]
fn the_core_builds_without_the_crates_that_talk_to_the_world() {
    let core = resolved_dependencies("ratelab-core");
    assert!(
        core.contains("ratelab-core") && core.contains("serde"),
        "{core:?}"
    );
    for heavy in [
        "zenoh",
        "rerun",
        "pyo3",
        "candle-core",
        "tract-onnx",
        "mujoco-rs",
    ] {
        assert!(!core.contains(heavy), "ratelab-core is built with {heavy}");
    }
    // The runtime embeds no Python and speaks no Zenoh: the Python and ROS 2 layers sit
    // above it, and the recordings are built without Zenoh.
    let runtime = resolved_dependencies("ratelab-runtime");
    for heavy in ["pyo3", "zenoh"] {
        assert!(
            !runtime.contains(heavy),
            "ratelab-runtime is built with {heavy}"
        );
    }
    assert!(!resolved_dependencies("ratelab-recording").contains("zenoh"));
    // And no library layer draws on a terminal: none is built with ratatui, none names
    // crossterm (which rerun's own dependencies bring along) — the lab alone draws.
    let lab = resolved_dependencies("ratelab-lab");
    assert!(
        lab.contains("ratatui") && lab.contains("crossterm"),
        "{lab:?}"
    );
    // The lab's crate and the wheel's module above it hold the terminal lab and the command
    // line; the Python API is built with neither (issue 71 item 3, `cargo tree`).
    let below_the_lab = |p: &&str| !matches!(*p, "ratelab-lab" | "ratelab-wheel");
    for (package, dir, _) in LAYERS.iter().filter(|(p, ..)| below_the_lab(p)) {
        let deps = resolved_dependencies(package);
        assert!(!deps.contains("ratatui"), "{package} is built with ratatui");
        assert!(!deps.contains("clap"), "{package} is built with clap");
        assert!(
            !deps.contains("ratelab-lab"),
            "{package} is built with the terminal crate"
        );
        assert!(
            !manifest_dependencies(dir).contains("crossterm"),
            "{package} depends on crossterm"
        );
    }
}

#[test]
fn no_crate_of_the_library_has_an_import_cycle() {
    let deps = |dir: &str| dependencies(&crate::repo(dir));
    let core = deps("src/core");
    let runtime = deps("src/runtime");
    // The scan sees what it must: the run log imports the ids, the graph file format the
    // plant; the core's modules are not the runtime's, nor the crates' the facade's.
    assert!(core["runlog"].contains("ids"), "{:?}", core["runlog"]);
    assert!(
        runtime["graph::spec"].contains("plant"),
        "{:?}",
        runtime["graph::spec"]
    );
    assert!(!runtime.contains_key("qos") && core.contains_key("qos"));
    let facade = deps("src");
    assert!(!facade.contains_key("exercise") && !facade.contains_key("graph"));
    assert!(deps("src/exercises").contains_key("ex14"));
    // Every crate, the lab's too, its modules among their siblings, a parent with its
    // children (issue "One front-end kit…", item 5's parent→child edges). Every cycle is
    // named (each found, then cut at its first edge, and the search goes on).
    let mut cycles = Vec::new();
    for (_, dir, _) in LAYERS {
        let (mut siblings, because) = between_siblings(&deps(dir));
        while let Some(cycle) = find_cycle(&siblings) {
            let through: Vec<String> = cycle
                .windows(2)
                .map(|w| {
                    let (a, b) = &because[&(w[0].clone(), w[1].clone())];
                    format!("{a} uses {b}")
                })
                .collect();
            cycles.push(format!(
                "import cycle in {dir}: {} ({})",
                cycle.join(" → "),
                through.join("; ")
            ));
            siblings.get_mut(&cycle[0]).unwrap().remove(&cycle[1]);
        }
    }
    assert!(cycles.is_empty(), "{}", cycles.join("\n"));
}

/// A child's use of its parent is containment; a parent's child that needs a module that
/// needs the parent is a cycle of the parent's and that module's.
#[test]
fn a_cycle_through_a_parent_s_child_is_found() {
    let deps: Deps = [
        ("tui::view", &["tui::view::graph"][..]),
        ("tui::view::graph", &["tui::view", "tui::navigate"][..]),
        ("tui::navigate", &["tui::view"][..]),
        ("tui", &["tui::view"][..]),
    ]
    .into_iter()
    .map(|(m, d)| (m.to_string(), d.iter().map(|s| s.to_string()).collect()))
    .collect();
    let (siblings, because) = between_siblings(&deps);
    assert_eq!(
        find_cycle(&siblings).unwrap(),
        ["tui::navigate", "tui::view", "tui::navigate"]
    );
    assert_eq!(
        because[&("tui::view".to_string(), "tui::navigate".to_string())],
        ("tui::view::graph".to_string(), "tui::navigate".to_string())
    );
    let mut acyclic = deps.clone();
    acyclic.get_mut("tui::navigate").unwrap().clear();
    assert_eq!(find_cycle(&between_siblings(&acyclic).0), None);
}

#[test]
fn a_cycle_is_found_and_named() {
    let deps: Deps = [
        ("config", &["graph::spec"][..]),
        ("graph::spec", &["qos", "time"][..]),
        ("qos", &["config", "time"][..]),
        ("time", &[][..]),
    ]
    .into_iter()
    .map(|(m, d)| (m.to_string(), d.iter().map(|s| s.to_string()).collect()))
    .collect();
    assert_eq!(
        find_cycle(&deps).unwrap(),
        ["config", "graph::spec", "qos", "config"]
    );
    let mut acyclic = deps.clone();
    acyclic.get_mut("qos").unwrap().remove("config");
    assert_eq!(find_cycle(&acyclic), None);
}

#[test]
fn paths_in_code_and_macros_count_and_doc_comments_and_tests_do_not() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    std::fs::create_dir(src.join("graph")).unwrap();
    std::fs::write(
        src.join("lib.rs"),
        "pub mod graph; pub mod metrics; pub mod time;",
    )
    .unwrap();
    std::fs::write(
        src.join("graph/mod.rs"),
        "pub mod spec;\n/// [`crate::metrics::M`]\npub fn f() { let _ = format!(\"{}\", crate::time::X); }\n\
         mod inner { fn g() -> u8 { super::super::time::X } }",
    )
    .unwrap();
    std::fs::write(
        src.join("graph/spec.rs"),
        "use super::super::time::X;\n#[cfg(test)]\nmod tests { use crate::metrics::M; }",
    )
    .unwrap();
    std::fs::write(src.join("metrics.rs"), "use crate::graph::spec::{self, *};").unwrap();
    std::fs::write(src.join("time.rs"), "pub const X: u8 = 0;").unwrap();
    let deps = dependencies(src);
    let set = |m: &str| deps[m].iter().cloned().collect::<Vec<_>>();
    assert_eq!(set("graph"), ["time"]);
    assert_eq!(set("graph::spec"), ["time"]);
    assert_eq!(set("metrics"), ["graph::spec"]);
    assert!(set("time").is_empty());
}

/// Each library crate's module map (its `lib.rs` header) names every module the crate has,
/// so a maintainer reading it first sees the whole crate (the library's once left out 8 of
/// 31); the facade's names every module it re-exports.
#[test]
fn every_crate_s_module_map_names_every_module() {
    let mut seen = 0;
    for (package, dir, _) in LAYERS.iter().filter(|(p, ..)| *p != "ratelab-lab") {
        let lib = std::fs::read_to_string(crate::repo(dir).join("lib.rs")).unwrap();
        let header: String = lib
            .lines()
            .take_while(|l| l.starts_with("//!"))
            .collect::<Vec<_>>()
            .join("\n");
        // `pub mod x;`, and the facade's re-exported modules (`pub use ratelab_core::{…}`).
        let mut modules: Vec<String> = lib
            .lines()
            .filter_map(|l| l.strip_prefix("pub mod "))
            .map(|l| l.trim_end_matches(';').to_string())
            .collect();
        if *package == "ratelab" {
            let file = syn::parse_file(&lib).unwrap();
            for item in file.items {
                if let syn::Item::Use(u) = item {
                    if matches!(u.vis, syn::Visibility::Public(_)) {
                        reexported(&u.tree, &mut modules);
                    }
                }
            }
        }
        seen += modules.len();
        let missing: Vec<&String> = modules
            .iter()
            .filter(|m| !header.contains(&format!("[`{m}`]")))
            .collect();
        assert!(
            missing.is_empty(),
            "{dir}/lib.rs's header omits {missing:?}"
        );
    }
    assert!(seen > 60, "{seen} modules");
}

/// The lowercase names a `pub use` re-exports (modules, and `run`, a module and its
/// function; types are capitalised).
fn reexported(tree: &syn::UseTree, out: &mut Vec<String>) {
    match tree {
        syn::UseTree::Path(p) => reexported(&p.tree, out),
        syn::UseTree::Name(n) => {
            let name = n.ident.to_string();
            if name.starts_with(|c: char| c.is_ascii_lowercase()) {
                out.push(name);
            }
        }
        syn::UseTree::Rename(r) => out.push(r.rename.to_string()),
        syn::UseTree::Glob(_) => {}
        syn::UseTree::Group(g) => g.items.iter().for_each(|t| reexported(t, out)),
    }
}

/// The string literals of one file's code (not its tests), also inside macro calls.
#[derive(Default)]
struct Literals(Vec<String>);

impl Literals {
    fn scan(&mut self, tokens: TokenStream) {
        for t in tokens {
            match t {
                TokenTree::Literal(l) => self.0.push(l.to_string()),
                TokenTree::Group(g) => self.scan(g.stream()),
                _ => {}
            }
        }
    }
}

impl<'ast> Visit<'ast> for Literals {
    fn visit_item(&mut self, item: &'ast syn::Item) {
        if !is_cfg_test(attrs(item)) {
            syn::visit::visit_item(self, item);
        }
    }

    fn visit_lit_str(&mut self, l: &'ast syn::LitStr) {
        self.0.push(format!("{:?}", l.value()));
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        self.scan(m.tokens.clone());
    }
}

/// Every `.rs` file under `dir`, recursively.
fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// An exercise is one file plus its line in the registry (issue "One run core…", item 5):
/// no code outside `src/exercises/exN.rs` names exercise `exN` (the command line, the lab,
/// the framework list them from the registry).
#[test]
fn an_exercise_is_named_only_in_its_own_file() {
    let mut files = Vec::new();
    rust_files(&crate::repo("src"), &mut files);
    rust_files(&crate::repo("lab"), &mut files);
    let ids = ratelab_exercises::ids();
    assert!(ids.len() >= 9, "{ids:?}");
    let mut found = 0;
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        let mut literals = Literals::default();
        literals.visit_file(&syn::parse_file(&text).unwrap());
        for id in &ids {
            let quoted = format!("{id:?}");
            if literals.0.contains(&quoted) {
                let own = file.ends_with(format!("src/exercises/{id}.rs"));
                assert!(own, "{} names {quoted}", file.display());
                found += 1;
            }
        }
    }
    assert_eq!(found, ids.len(), "each exercise names itself in its file");
}

/// The most lines of code a source file may hold, tests, comments and blank lines apart
/// (issue "One run core…", item 6).
const MAX_FILE_LINES: usize = 1_000;
/// The most lines a function may span, from its signature to its closing brace.
const MAX_FN_LINES: usize = 150;

/// Line spans (first, last; 1-based) of a file's test items, and each function's name
/// with its span.
#[derive(Default)]
struct Sizes {
    tests: Vec<(usize, usize)>,
    fns: Vec<(String, usize, usize)>,
}

fn lines_of(span: proc_macro2::Span) -> (usize, usize) {
    (span.start().line, span.end().line)
}

impl<'ast> Visit<'ast> for Sizes {
    fn visit_item(&mut self, item: &'ast syn::Item) {
        if is_cfg_test(attrs(item)) {
            self.tests.push(lines_of(syn::spanned::Spanned::span(item)));
        } else {
            syn::visit::visit_item(self, item);
        }
    }

    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        let (a, b) = lines_of(syn::spanned::Spanned::span(f));
        self.fns.push((f.sig.ident.to_string(), a, b));
        syn::visit::visit_item_fn(self, f);
    }

    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        let (a, b) = lines_of(syn::spanned::Spanned::span(f));
        self.fns.push((f.sig.ident.to_string(), a, b));
        syn::visit::visit_impl_item_fn(self, f);
    }

    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        let (a, b) = lines_of(syn::spanned::Spanned::span(f));
        self.fns.push((f.sig.ident.to_string(), a, b));
        syn::visit::visit_trait_item_fn(self, f);
    }
}

/// No source file holds more than [`MAX_FILE_LINES`] lines of code and no function spans
/// more than [`MAX_FN_LINES`] lines, so that a maintainer can read either whole.
#[test]
fn no_file_or_function_is_too_long_to_read() {
    let mut files = Vec::new();
    rust_files(&crate::repo("src"), &mut files);
    rust_files(&crate::repo("lab"), &mut files);
    let mut over = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let mut sizes = Sizes::default();
        sizes.visit_file(&syn::parse_file(&text).unwrap());
        let in_tests = |n: usize| sizes.tests.iter().any(|&(a, b)| (a..=b).contains(&n));
        let code = text
            .lines()
            .enumerate()
            .filter(|&(i, l)| {
                let l = l.trim();
                !l.is_empty() && !l.starts_with("//") && !in_tests(i + 1)
            })
            .count();
        let name = file.strip_prefix(crate::repo("")).unwrap_or(file).display();
        if code > MAX_FILE_LINES {
            over.push(format!("{name}: {code} lines of code"));
        }
        for (f, a, b) in &sizes.fns {
            if b - a + 1 > MAX_FN_LINES && !in_tests(*a) {
                over.push(format!("{name}: fn {f}, {} lines", b - a + 1));
            }
        }
    }
    assert!(files.len() > 100, "{} files", files.len());
    assert!(over.is_empty(), "too long to read:\n{}", over.join("\n"));
}

/// The modules of other workspace crates a `use` item brings under a name of this crate
/// (`use ratelab_core::{time, qos};`, `use ratelab_ros2 as ros2;`): with one, `crate::time`
/// in a line of this crate is another crate's module, which the line does not say. A name
/// counts as a module when it is one of `modules` (the workspace's top-level modules) and is
/// imported straight from a crate's root; a function or type (`ratelab::text::printable`)
/// is not.
fn module_aliases(
    tree: &syn::UseTree,
    depth: usize,
    modules: &BTreeSet<String>,
    out: &mut Vec<String>,
) {
    match tree {
        syn::UseTree::Path(p) => {
            if depth == 0 && !p.ident.to_string().starts_with("ratelab") {
                return;
            }
            module_aliases(&p.tree, depth + 1, modules, out);
        }
        syn::UseTree::Name(n) if depth == 1 && modules.contains(&n.ident.to_string()) => {
            out.push(n.ident.to_string());
        }
        syn::UseTree::Rename(r) => {
            let name = r.ident.to_string();
            if (depth == 0 && name.starts_with("ratelab"))
                || (depth == 1 && modules.contains(&name))
            {
                out.push(format!("{name} as {}", r.rename));
            }
        }
        syn::UseTree::Group(g) => g
            .items
            .iter()
            .for_each(|t| module_aliases(t, depth, modules, out)),
        _ => {}
    }
}

/// Issue "One front-end kit…", item 5: no crate of the library names another crate's
/// module as its own (`crate::plant` was the core's plant in one crate and the runtime's in
/// another); a line names the crate it uses (`ratelab_runtime::plant`). The facade's public
/// re-exports are its API, not aliases, and stay.
#[test]
fn no_crate_aliases_another_crate_s_modules() {
    // Every crate's top-level modules, and the facade's re-exported ones.
    let mut modules = BTreeSet::new();
    for (package, dir, _) in LAYERS {
        let lib = std::fs::read_to_string(crate::repo(dir).join("lib.rs")).unwrap();
        for l in lib.lines() {
            if let Some(m) = l.strip_prefix("pub mod ") {
                modules.insert(m.trim_end_matches(';').to_string());
            }
        }
        if *package == "ratelab" {
            let mut reexports = Vec::new();
            for item in syn::parse_file(&lib).unwrap().items {
                if let syn::Item::Use(u) = item {
                    if matches!(u.vis, syn::Visibility::Public(_)) {
                        reexported(&u.tree, &mut reexports);
                    }
                }
            }
            modules.extend(reexports);
        }
    }
    assert!(
        modules.contains("time") && modules.contains("graph"),
        "{modules:?}"
    );
    let aliases = |t: &str| -> Vec<String> {
        let file = syn::parse_file(t).unwrap();
        let mut out = Vec::new();
        for item in file.items {
            if let syn::Item::Use(u) = item {
                if !matches!(u.vis, syn::Visibility::Public(_)) {
                    module_aliases(&u.tree, 0, &modules, &mut out);
                }
            }
        }
        out
    };
    // The scan finds what it must, and only that.
    assert_eq!(
        aliases(
            "use ratelab_core::{time, Nanos, qos::Qos};\nuse ratelab_ros2 as ros2;\n\
             use ratelab::text::printable;\nuse std::fmt;\npub use ratelab_core::plant;"
        ),
        ["time", "ratelab_ros2 as ros2"]
    );
    for (_, dir, _) in LAYERS {
        let lib = std::fs::read_to_string(crate::repo(dir).join("lib.rs")).unwrap();
        let found = aliases(&lib);
        assert!(
            found.is_empty(),
            "{dir}/lib.rs brings other crates' modules under its own name: {found:?}"
        );
    }
}

/// Issue "One front-end kit…", item 5: every crate warns of a public item without docs
/// (and CI's clippy makes the warning an error).
#[test]
fn every_crate_warns_of_a_public_item_without_docs() {
    for (_, dir, _) in LAYERS {
        let lib = std::fs::read_to_string(crate::repo(dir).join("lib.rs")).unwrap();
        assert!(
            lib.lines().any(|l| l.trim() == "#![warn(missing_docs)]"),
            "{dir}/lib.rs lacks #![warn(missing_docs)]"
        );
    }
}

/// Every trait in `file` (at any depth of inline modules, `#[cfg(test)]` items left out) that
/// declares a method named `tick`, as `Trait (pub)` or `Trait`.
fn traits_with_a_tick(items: &[syn::Item], out: &mut Vec<String>) {
    for item in items {
        if is_cfg_test(attrs(item)) {
            continue;
        }
        match item {
            syn::Item::Trait(t) => {
                let ticks = t.items.iter().any(|i| match i {
                    syn::TraitItem::Fn(f) => f.sig.ident == "tick",
                    _ => false,
                });
                if ticks {
                    let public = matches!(t.vis, syn::Visibility::Public(_));
                    out.push(format!("{}{}", t.ident, if public { " (pub)" } else { "" }));
                }
            }
            syn::Item::Mod(m) => {
                if let Some((_, inner)) = &m.content {
                    traits_with_a_tick(inner, out);
                }
            }
            _ => {}
        }
    }
}

/// One node trait (issue "One front-end kit…", item 4): the only public trait in the library
/// and the lab that declares a `tick` is `ratelab_core::ports::RustNode`, which every kind
/// implements, built in or a program's own; the schedulers run one concrete type around it
/// (`GraphNode`). The one other trait with a `tick` is the graph's type-erased side of a
/// `RustNode` (`graph::kind::Work`, crate-private, never written by a kind).
#[test]
fn one_node_trait_is_public() {
    let mut found = Vec::new();
    for (_, dir, _) in LAYERS {
        let mut files = Vec::new();
        rust_files(&crate::repo(dir), &mut files);
        for path in files {
            let text = std::fs::read_to_string(&path).unwrap();
            let file = syn::parse_file(&text).unwrap();
            let mut traits = Vec::new();
            traits_with_a_tick(&file.items, &mut traits);
            let rel = path
                .strip_prefix(crate::repo(""))
                .unwrap_or(&path)
                .display();
            found.extend(traits.into_iter().map(|t| format!("{rel}: {t}")));
        }
    }
    found.sort();
    found.dedup(); // the facade's folder holds the other crates' folders
    assert_eq!(
        found,
        [
            "src/core/ports.rs: RustNode (pub)",
            "src/runtime/graph/kind.rs: Work"
        ],
        "a trait with a tick other than RustNode and the graph's Work"
    );
}
