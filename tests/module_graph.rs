//! Data flows one way through the crate's modules: no file imports an item
//! of a module that imports it back, directly or through others
//! (ARCHITECTURE.md). The graph is read from the sources: every `use` and
//! every `crate::`, `super::`, `self::` or child-module path in code (tests
//! and comments left out), each followed to the file that defines the item,
//! through `pub use` re-exports. A parent `mod.rs` that uses its children
//! must therefore not define what they import.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module path ("" for the crate root, "backend::gpu::sweep") → its source,
/// stripped of comments, strings and its test module.
fn modules() -> BTreeMap<String, (bool, String)> {
    fn walk(dir: &Path, prefix: &[String], out: &mut BTreeMap<String, (bool, String)>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_stem().unwrap().to_str().unwrap().to_owned();
            if path.is_dir() {
                let mut p = prefix.to_vec();
                p.push(name);
                walk(&path, &p, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let mut p = prefix.to_vec();
                let is_dir_module = name == "mod" || (prefix.is_empty() && name == "lib");
                if prefix.is_empty() && name == "main" {
                    continue;
                }
                if !is_dir_module {
                    p.push(name);
                }
                let source = strip(&std::fs::read_to_string(&path).unwrap());
                out.insert(p.join("::"), (is_dir_module, source));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("src"),
        &[],
        &mut out,
    );
    out
}

/// The source without comments, string and character literals, and test
/// modules.
fn strip(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::new();
    let mut i = 0;
    let at = |i: usize, s: &str| s.chars().enumerate().all(|(k, c)| b.get(i + k) == Some(&c));
    while i < b.len() {
        if at(i, "//") {
            while i < b.len() && b[i] != '\n' {
                i += 1;
            }
        } else if at(i, "/*") {
            i += 2;
            while i < b.len() && !at(i, "*/") {
                i += 1;
            }
            i += 2;
        } else if b[i] == 'r'
            && (b.get(i + 1) == Some(&'#') || b.get(i + 1) == Some(&'"'))
            && (i == 0 || !(b[i - 1].is_alphanumeric() || b[i - 1] == '_'))
        {
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(b[i]);
                i += 1;
                continue;
            }
            j += 1;
            let close: String = std::iter::once('"')
                .chain((0..hashes).map(|_| '#'))
                .collect();
            while j < b.len() && !at(j, &close) {
                j += 1;
            }
            i = j + close.len();
            out.push_str("\"\"");
        } else if b[i] == '"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != '"' {
                j += if b[j] == '\\' { 2 } else { 1 };
            }
            i = j + 1;
            out.push_str("\"\"");
        } else if b[i] == '\'' && b.get(i + 2) == Some(&'\'') && b[i + 1] != '\\' {
            i += 3;
            out.push_str("' '");
        } else if b[i] == '\'' && b.get(i + 1) == Some(&'\\') {
            let mut j = i + 2;
            while j < b.len() && b[j] != '\'' {
                j += 1;
            }
            i = j + 1;
            out.push_str("' '");
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    match out.find("#[cfg(test)]\nmod tests") {
        Some(k) => out[..k].to_owned(),
        None => out,
    }
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The names a module defines at its top level (fn, struct, enum, trait,
/// const, static, type, macro).
fn definitions(source: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for line in source.lines() {
        let mut words = line
            .split(|c: char| !is_ident(c) && c != '!')
            .filter(|w| !w.is_empty());
        while let Some(w) = words.next() {
            if matches!(
                w,
                "fn" | "struct" | "enum" | "trait" | "const" | "static" | "type" | "macro_rules!"
            ) {
                if let Some(name) = words.next() {
                    names.insert(name.to_owned());
                }
                break;
            }
            if !matches!(
                w,
                "pub" | "crate" | "super" | "unsafe" | "async" | "extern" | "in"
            ) {
                break;
            }
        }
    }
    names
}

/// `a::{b, c::{d, e}}` as `a::b`, `a::c::d`, `a::c::e`.
fn expand(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else {
        return vec![tree.to_owned()];
    };
    let (prefix, inner) = (&tree[..open], &tree[open + 1..tree.len() - 1]);
    let mut items = Vec::new();
    let (mut depth, mut current) = (0, String::new());
    for c in inner.chars() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            _ => {}
        }
        if c == ',' && depth == 0 {
            items.push(std::mem::take(&mut current));
        } else {
            current.push(c);
        }
    }
    items.push(current);
    items
        .iter()
        .filter(|i| !i.trim().is_empty())
        .flat_map(|i| expand(i).into_iter().map(|e| format!("{prefix}{e}")))
        .collect()
}

/// The `use` statements of a module: (public, path).
fn uses(source: &str) -> Vec<(bool, String)> {
    let mut out = Vec::new();
    let mut rest = source;
    while let Some(k) = rest.find("use ") {
        let before = &rest[..k];
        let line_start = before.rfind('\n').map_or(0, |n| n + 1);
        let head = before[line_start..].trim();
        let statement_start = head.is_empty() || head.starts_with("pub");
        let boundary = k == 0 || !is_ident(before.chars().last().unwrap());
        rest = &rest[k + 4..];
        if !(statement_start && boundary) {
            continue;
        }
        let end = rest.find(';').unwrap_or(rest.len());
        for path in expand(&rest[..end].split_whitespace().collect::<Vec<_>>().join(" ")) {
            let path = path.split(" as ").next().unwrap().trim().replace(' ', "");
            let path = path.strip_suffix("::self").unwrap_or(&path).to_owned();
            out.push((head.starts_with("pub"), path));
        }
    }
    out
}

struct Crate {
    modules: BTreeMap<String, (bool, String)>,
    definitions: BTreeMap<String, BTreeSet<String>>,
    uses: BTreeMap<String, Vec<(bool, String)>>,
}

impl Crate {
    /// The segments of `path` written in module `m`, from the crate root.
    fn absolute(&self, m: &str, path: &str) -> Vec<String> {
        let own: Vec<String> = if m.is_empty() {
            vec![]
        } else {
            m.split("::").map(String::from).collect()
        };
        let mut segments: Vec<&str> = path.split("::").collect();
        let mut base = match segments[0] {
            "crate" => {
                segments.remove(0);
                vec![]
            }
            "self" => {
                segments.remove(0);
                own
            }
            "super" => {
                let mut base = own;
                while segments.first() == Some(&"super") {
                    segments.remove(0);
                    base.pop();
                }
                base
            }
            _ => own,
        };
        base.extend(segments.iter().map(|s| s.to_string()));
        base
    }

    /// The module that defines what `segments` names, through re-exports.
    fn target(&self, segments: &[String], depth: usize) -> Option<String> {
        let k = (0..=segments.len())
            .rev()
            .find(|&k| self.modules.contains_key(&segments[..k].join("::")))?;
        let module = segments[..k].join("::");
        if let (Some(item), true) = (segments.get(k), depth < 10) {
            if !self.definitions[&module].contains(item) {
                for (public, path) in &self.uses[&module] {
                    if *public && path.rsplit("::").next() == Some(item.as_str()) {
                        if let Some(t) = self.target(&self.absolute(&module, path), depth + 1) {
                            return Some(t);
                        }
                    }
                }
            }
        }
        Some(module)
    }

    fn edges(&self) -> BTreeMap<String, BTreeSet<String>> {
        let mut edges = BTreeMap::new();
        for (m, (_, source)) in &self.modules {
            let children: BTreeSet<String> = self
                .modules
                .keys()
                .filter_map(|c| {
                    let rest = if m.is_empty() {
                        Some(c.as_str())
                    } else {
                        c.strip_prefix(&format!("{m}::"))
                    };
                    rest.filter(|r| !r.is_empty() && !r.contains("::"))
                        .map(String::from)
                })
                .collect();
            let mut paths: Vec<String> = self.uses[m]
                .iter()
                .map(|(_, p)| p.clone())
                .filter(|p| {
                    let first = p.split("::").next().unwrap();
                    matches!(first, "crate" | "super" | "self") || children.contains(first)
                })
                .collect();
            // Paths in code: crate::a::b, super::c, self::d, child::e.
            let chars: Vec<char> = source.chars().collect();
            let mut i = 0;
            while i < chars.len() {
                if is_ident(chars[i])
                    && (i == 0 || !(is_ident(chars[i - 1]) || chars[i - 1] == ':'))
                {
                    let mut j = i;
                    while j < chars.len() && (is_ident(chars[j]) || chars[j] == ':') {
                        j += 1;
                    }
                    let path: String = chars[i..j].iter().collect();
                    let path = path.trim_end_matches(':');
                    let first = path.split("::").next().unwrap();
                    if path.contains("::")
                        && (matches!(first, "crate" | "super" | "self") || children.contains(first))
                    {
                        paths.push(path.to_owned());
                    }
                    i = j;
                } else {
                    i += 1;
                }
            }
            let targets: BTreeSet<String> = paths
                .iter()
                .filter_map(|p| self.target(&self.absolute(m, p), 0))
                .filter(|t| t != m)
                .collect();
            edges.insert(m.clone(), targets);
        }
        edges
    }
}

/// The strongly connected components of more than one module (Tarjan).
fn circles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        edges: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        found: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in &s.edges[v] {
            let w = w.as_str();
            if !s.index.contains_key(w) {
                visit(s, w);
                let low = s.low[v].min(s.low[w]);
                s.low.insert(v, low);
            } else if s.on_stack.contains(w) {
                let low = s.low[v].min(s.index[w]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on_stack.remove(w);
                component.push(w.to_owned());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                s.found.push(component);
            }
        }
    }
    let mut s = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        found: Vec::new(),
    };
    for v in edges.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.found
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let modules = modules();
    let krate = Crate {
        definitions: modules
            .iter()
            .map(|(m, (_, s))| (m.clone(), definitions(s)))
            .collect(),
        uses: modules
            .iter()
            .map(|(m, (_, s))| (m.clone(), uses(s)))
            .collect(),
        modules,
    };
    let edges = krate.edges();
    // The reader sees real edges: the backend uses the method, the method
    // never the backend.
    assert!(
        edges["backend"].contains("method::lane::driver"),
        "{:?}",
        edges["backend"]
    );
    assert!(
        edges["output"].contains("model::compiled"),
        "{:?}",
        edges["output"]
    );
    let found = circles(&edges);
    let report: Vec<String> = found
        .iter()
        .map(|c| {
            let inside: BTreeSet<&String> = c.iter().collect();
            let arrows: Vec<String> = c
                .iter()
                .flat_map(|a| {
                    edges[a]
                        .iter()
                        .filter(|b| inside.contains(b))
                        .map(move |b| format!("  {a} -> {b}"))
                })
                .collect();
            format!("{c:?}\n{}", arrows.join("\n"))
        })
        .collect();
    assert!(found.is_empty(), "import circles:\n{}", report.join("\n"));
}
