//! The layout's rules, checked on the source tree (docs/ARCHITECTURE.md):
//! - dependencies point one way: `cli` → `ops` → `sql` → `dataset` → `io` → `kernels` (the command
//!   line also opens the `dataset` handle it hands to an operation), and every
//!   layer may use `error`; kernels use nothing but kernels (no files, no Arrow, no Parquet: they
//!   are a package of their own, `src/kernels/Cargo.toml`, whose `crate::` is `kernels`);
//! - `dataset/` is the store: it takes the kernels' types and constants, never a function;
//! - no module imports one of its importers (no cycle between the modules of the tree);
//! - no line is wider than `rustfmt.toml`'s `max_width` (rustfmt leaves long strings alone).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// What each layer may use, besides itself.
fn allowed(layer: &str) -> &'static [&'static str] {
    match layer {
        // The error takes in the kernels' own (`From<kernels::error::Error>`).
        "error" => &["kernels"],
        "kernels" => &[],
        "io" => &["kernels", "error"],
        "dataset" => &["io", "kernels", "error"],
        "sql" => &["dataset", "io", "kernels", "error"],
        "ops" => &["sql", "dataset", "io", "kernels", "error"],
        "cli" => &["ops", "dataset", "kernels", "error"],
        other => panic!(
            "src/{other}: a folder the layout does not name (add it to tests/layout.rs and docs/ARCHITECTURE.md)"
        ),
    }
}

/// Crates that read or write files or Arrow data: a kernel must not name them.
const IO_CRATES: [&str; 8] = ["arrow", "parquet", "datafusion", "hdf5", "las", "tiff", "plotters", "std::fs"];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module a file belongs to, at the depth the rules speak of: `kernels::sim`, `dataset::als`,
/// `dataset` (its mod.rs), `cli` (main.rs and src/cli/).
fn module_of(file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src()).unwrap();
    let parts: Vec<String> = rel.iter().map(|s| s.to_string_lossy().trim_end_matches(".rs").to_string()).collect();
    match parts.as_slice() {
        [f] if f == "lib" => None,
        [f] if f == "main" => Some("cli".into()),
        [f] => Some(f.clone()),
        [top, ..] if top == "cli" => Some("cli".into()),
        [top, f] if f == "mod" => Some(top.clone()),
        [top, sub, ..] => Some(format!("{top}::{sub}")),
        [] => None,
    }
}

/// The module a path `A::B::…` names: `A::B` when `src/A/B.rs` or `src/A/B/` exists, else `A`.
fn module_named(a: &str, b: Option<&str>) -> String {
    match b {
        Some(b) if src().join(a).join(format!("{b}.rs")).exists() || src().join(a).join(b).is_dir() => {
            format!("{a}::{b}")
        }
        _ => a.to_string(),
    }
}

/// Source text without comments (line comments and doc comments), where paths in prose live.
fn code_of(text: &str) -> String {
    text.lines().map(|l| l.split_once("//").map_or(l, |(code, _)| code)).collect::<Vec<_>>().join("\n")
}

/// Every module each module's code names, with the first line naming it.
fn edges() -> BTreeMap<String, BTreeMap<String, String>> {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut out: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for f in files {
        let Some(from) = module_of(&f) else { continue };
        let text = std::fs::read_to_string(&f).unwrap();
        let prefix = if from == "cli" { "gedisim::" } else { "crate::" };
        let in_kernels = layer(&from) == "kernels";
        for (n, line) in code_of(&text).lines().enumerate() {
            let mut rest = line;
            while let Some(i) = rest.find(prefix) {
                rest = &rest[i + prefix.len()..];
                let names: Vec<&str> = rest
                    .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                    .next()
                    .unwrap_or("")
                    .split("::")
                    .collect();
                let to = match names.first() {
                    // The kernels' `crate::` is the kernels package.
                    Some(a) if in_kernels && !a.is_empty() => module_named("kernels", Some(a)),
                    Some(&"Error") | Some(&"Result") => "error".to_string(),
                    Some(a) if !a.is_empty() => module_named(a, names.get(1).copied()),
                    _ => continue,
                };
                if to != from {
                    let at = format!("{}:{}", f.strip_prefix(src()).unwrap().display(), n + 1);
                    out.entry(from.clone()).or_default().entry(to).or_insert(at);
                }
            }
        }
    }
    out
}

fn layer(module: &str) -> &str {
    module.split("::").next().unwrap()
}

#[test]
fn dependencies_point_one_way() {
    let mut wrong = Vec::new();
    for (from, tos) in edges() {
        for (to, at) in tos {
            let (lf, lt) = (layer(&from), layer(&to));
            if lf != lt && !allowed(lf).contains(&lt) {
                wrong.push(format!("{at}: {from} uses {to}"));
            }
        }
    }
    assert!(wrong.is_empty(), "dependencies against the layout:\n{}", wrong.join("\n"));
}

#[test]
fn kernels_do_no_io() {
    let mut files = Vec::new();
    rust_files(&src().join("kernels"), &mut files);
    let mut wrong = Vec::new();
    for f in files {
        let code = code_of(&std::fs::read_to_string(&f).unwrap());
        for (n, line) in code.lines().enumerate() {
            for c in IO_CRATES {
                let named = line.contains(&format!("{c}::")) && !line.contains(&format!("_{c}::"));
                if named
                    && (line.trim_start().starts_with("use ")
                        || line.contains(&format!(" {c}::"))
                        || line.contains(&format!("({c}::")))
                {
                    wrong.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "kernels naming I/O crates:\n{}", wrong.join("\n"));
}

#[test]
fn the_binary_does_not_read_the_source_tree() {
    // An installed binary has no source tree: only tests may find files through the build-time
    // manifest folder (the demo's inputs are embedded, `io::bundled`).
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut wrong = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let shipped = text.split("#[cfg(test)]").next().unwrap_or_default();
        for (n, line) in code_of(shipped).lines().enumerate() {
            if line.contains("CARGO_MANIFEST_DIR") {
                wrong.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(wrong.is_empty(), "paths of the source tree in shipped code:\n{}", wrong.join("\n"));
}

#[test]
fn no_module_imports_one_of_its_importers() {
    let g = edges();
    // A module reaches its importer when a path leads back to it.
    let mut cycles = BTreeSet::new();
    for start in g.keys() {
        let mut stack: Vec<(String, Vec<String>)> = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((m, path)) = stack.pop() {
            for next in g.get(&m).map(|t| t.keys().cloned().collect::<Vec<_>>()).unwrap_or_default() {
                if &next == start {
                    let mut c = path.clone();
                    c.push(next.clone());
                    let mut key = c[..c.len() - 1].to_vec();
                    key.sort();
                    if cycles.insert(key) {
                        let hops: Vec<String> =
                            c.windows(2).map(|w| format!("{} ({})", w[0], g[&w[0]][&w[1]])).collect();
                        eprintln!("cycle: {} → {}", hops.join(" → "), start);
                    }
                } else if seen.insert(next.clone()) {
                    let mut p = path.clone();
                    p.push(next.clone());
                    stack.push((next, p));
                }
            }
        }
    }
    assert!(cycles.is_empty(), "{} cycles between modules (listed above)", cycles.len());
}

/// The names a line of code takes from the kernels: the last segment of each `kernels::…` path,
/// and every name of a `kernels::…::{…}` list.
fn kernel_names(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("kernels::") {
        rest = &rest[i + "kernels::".len()..];
        let path: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':').collect();
        let after = &rest[path.len()..];
        if path.ends_with("::") && after.starts_with('{') {
            let list = &after[1..after.find('}').unwrap_or(after.len())];
            out.extend(list.split(',').map(|n| n.trim().to_string()).filter(|n| !n.is_empty()));
        } else {
            out.push(path.rsplit("::").next().unwrap_or("").to_string());
        }
    }
    out
}

#[test]
fn the_store_calls_no_kernel() {
    // `dataset/` is the store (docs/ARCHITECTURE.md): it holds the kernels' values (types and
    // constants, whose names begin with a capital) and never takes one of their functions or a
    // whole kernel module (`sim::simulate`, `sim::{self, …}`): what computes lives in `sql/` or `ops/`.
    let mut files = Vec::new();
    rust_files(&src().join("dataset"), &mut files);
    let mut wrong = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for (n, line) in code_of(&text).lines().enumerate() {
            for name in kernel_names(line) {
                if !name.starts_with(|c: char| c.is_ascii_uppercase()) {
                    wrong.push(format!("{}:{}: `{name}` in {}", f.display(), n + 1, line.trim()));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "the store calls kernels:\n{}", wrong.join("\n"));
}

#[test]
fn kernel_names_reads_paths_and_lists() {
    assert_eq!(kernel_names("use crate::kernels::sim::{self, Footprint};"), ["self", "Footprint"]);
    assert_eq!(kernel_names("let r = crate::kernels::sim::footprint::read_radius(s);"), ["read_radius"]);
    assert_eq!(kernel_names("use crate::kernels::gedi::N_ALGORITHMS;"), ["N_ALGORITHMS"]);
}

#[test]
fn every_top_level_folder_is_a_layer() {
    for e in std::fs::read_dir(src()).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            let _ = allowed(&name);
            let doc =
                std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/ARCHITECTURE.md")).unwrap();
            assert!(doc.contains(&format!("`src/{name}/`")), "docs/ARCHITECTURE.md does not map src/{name}/");
        }
    }
}

#[test]
fn no_line_is_wider_than_rustfmt_toml() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = std::fs::read_to_string(root.join("rustfmt.toml")).unwrap();
    let width: usize = config
        .lines()
        .find_map(|l| l.strip_prefix("max_width"))
        .and_then(|v| v.trim().trim_start_matches('=').trim().parse().ok())
        .expect("rustfmt.toml sets max_width");
    let mut files = Vec::new();
    for dir in ["src", "tests", "benches"] {
        rust_files(&root.join(dir), &mut files);
    }
    let mut wide = Vec::new();
    for f in files {
        for (n, line) in std::fs::read_to_string(&f).unwrap().lines().enumerate() {
            if line.chars().count() > width {
                wide.push(format!("{}:{}: {} characters", f.display(), n + 1, line.chars().count()));
            }
        }
    }
    assert!(wide.is_empty(), "lines wider than {width} (rustfmt does not wrap strings):\n{}", wide.join("\n"));
}
