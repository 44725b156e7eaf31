//! Data flows one way through the crate's modules, in the order that
//! ARCHITECTURE.md states under "Modules, bottom to top": every top-level
//! module of src/ is listed there once, and no file imports an item of a
//! module listed after its own; within a module, no file imports an item of
//! a module that imports it back, directly or through others. The order is
//! read from that list, so the map and this test cannot drift apart. The
//! graph is read from the sources: every `use` and every `crate::`,
//! `super::`, `self::` or child-module path in code (tests and comments left
//! out), each followed to the file that defines the item, through `pub use`
//! re-exports. A parent `mod.rs` that uses its children must therefore not
//! define what they import.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module path ("" for the crate root, "backend::gpu::sweep") → its file
/// (from the repository's root) and its source, stripped of comments,
/// strings and its test module.
fn modules() -> BTreeMap<String, (String, String)> {
    fn walk(dir: &Path, prefix: &[String], out: &mut BTreeMap<String, (String, String)>) {
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
                let file = path.strip_prefix(root()).unwrap().display().to_string();
                out.insert(p.join("::"), (file, source));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(&root().join("src"), &[], &mut out);
    out
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
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
    // The test module, to its closing brace: code after it still counts.
    let Some(k) = out.find("#[cfg(test)]\nmod tests") else {
        return out;
    };
    let mut depth = 0;
    let mut end = out.len();
    for (i, c) in out[k..].char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 1 => {
                end = k + i + 1;
                break;
            }
            '}' => depth -= 1,
            ';' if depth == 0 => {
                end = k + i + 1;
                break;
            }
            _ => {}
        }
    }
    format!("{}{}", &out[..k], &out[end..])
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
    modules: BTreeMap<String, (String, String)>,
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

    /// Module → the modules it imports → the paths, as written, that
    /// import each.
    fn imports(&self) -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
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
                    // `a::b::{c, d}` names c and d, which the uses list
                    // has, not the module a::b itself.
                    let group = path.ends_with("::") && chars.get(j) == Some(&'{');
                    let path = path.trim_end_matches(':');
                    let first = path.split("::").next().unwrap();
                    if !group
                        && path.contains("::")
                        && (matches!(first, "crate" | "super" | "self") || children.contains(first))
                    {
                        paths.push(path.to_owned());
                    }
                    i = j;
                } else {
                    i += 1;
                }
            }
            let mut targets: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
            for p in &paths {
                if let Some(t) = self.target(&self.absolute(m, p), 0).filter(|t| t != m) {
                    targets.entry(t).or_default().insert(p.clone());
                }
            }
            edges.insert(m.clone(), targets);
        }
        edges
    }

    fn edges(&self) -> BTreeMap<String, BTreeSet<String>> {
        self.imports()
            .into_iter()
            .map(|(m, targets)| (m, targets.into_keys().collect()))
            .collect()
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

impl Crate {
    fn read() -> Crate {
        let modules = modules();
        Crate {
            definitions: modules
                .iter()
                .map(|(m, (_, s))| (m.clone(), definitions(s)))
                .collect(),
            uses: modules
                .iter()
                .map(|(m, (_, s))| (m.clone(), uses(s)))
                .collect(),
            modules,
        }
    }

    /// The top-level modules of src/ (those `lib.rs` declares).
    fn top_level(&self) -> BTreeSet<String> {
        self.modules
            .keys()
            .filter(|m| !m.is_empty())
            .map(|m| top(m).to_owned())
            .collect()
    }
}

fn top(module: &str) -> &str {
    module.split("::").next().unwrap()
}

/// The heading in ARCHITECTURE.md whose numbered list is the module order.
const ORDER_HEADING: &str = "## Modules, bottom to top";

/// The entries of the numbered list under [`ORDER_HEADING`], in order: each
/// item's first code span, `src/NAME.rs` or `src/NAME/` for the module NAME,
/// or a front end outside the library (`src/main.rs`, `python/`), kept as
/// written.
fn stated_order(doc: &str) -> Result<Vec<String>, String> {
    let mut lines = doc.lines().skip_while(|l| l.trim_end() != ORDER_HEADING);
    if lines.next().is_none() {
        return Err(format!("ARCHITECTURE.md has no heading `{ORDER_HEADING}`"));
    }
    let mut order = Vec::new();
    for line in lines.take_while(|l| !l.starts_with("## ")) {
        let Some((number, rest)) = line.split_once(". ") else {
            continue;
        };
        if number.is_empty() || !number.chars().all(|c| c.is_ascii_digit()) {
            continue;
        }
        if number != (order.len() + 1).to_string() {
            return Err(format!(
                "item {number} of the module order should be numbered {}: {line}",
                order.len() + 1
            ));
        }
        let span = rest
            .strip_prefix('`')
            .and_then(|r| r.split_once('`'))
            .map(|(span, _)| span)
            .ok_or_else(|| {
                format!("item {number} does not start with a path in backticks: {line}")
            })?;
        let entry = match span
            .strip_prefix("src/")
            .and_then(|n| n.strip_suffix(".rs").or_else(|| n.strip_suffix('/')))
        {
            Some("main") | None => span.to_owned(),
            Some(name) => name.to_owned(),
        };
        order.push(entry);
    }
    if order.is_empty() {
        return Err(format!("no numbered list under `{ORDER_HEADING}`"));
    }
    Ok(order)
}

/// What breaks the stated order: a top-level module missing from it or
/// listed twice, an entry that is neither a module nor a front end that
/// exists, and every import of a module from one listed after it (above it).
fn order_violations(
    order: &[String],
    top_level: &BTreeSet<String>,
    files: &BTreeMap<String, (String, String)>,
    imports: &BTreeMap<String, BTreeMap<String, BTreeSet<String>>>,
) -> Vec<String> {
    let mut found = Vec::new();
    let place = |m: &str| order.iter().position(|e| e == m);
    for m in top_level {
        match order.iter().filter(|e| *e == m).count() {
            1 => {}
            0 => found.push(format!(
                "{} is the top-level module `{m}`, which the order in ARCHITECTURE.md \
                 (`{ORDER_HEADING}`) does not list",
                files.get(m).map_or(format!("src/{m}"), |(f, _)| f.clone())
            )),
            n => found.push(format!("`{m}` is listed {n} times in the module order")),
        }
    }
    for e in order {
        let front_end = e.contains('/') && root().join(e).exists();
        if !(top_level.contains(e) || front_end) {
            found.push(format!(
                "`{e}` in the module order is neither a top-level module of src/ nor a \
                 front end that exists"
            ));
        }
    }
    for (m, targets) in imports {
        let Some(from) = place(top(m)).filter(|_| !m.is_empty()) else {
            continue;
        };
        for (t, paths) in targets {
            let Some(to) = place(top(t)).filter(|&to| to > from) else {
                continue;
            };
            found.push(format!(
                "{} imports `{}` (defined in {t}): `{}` is {} in the module order, \
                 `{}` is {} (above it)",
                files[m].0,
                paths.iter().next().unwrap(),
                top(m),
                from + 1,
                top(t),
                to + 1
            ));
        }
    }
    found
}

#[test]
fn every_module_imports_only_modules_below_it_in_the_stated_order() {
    let krate = Crate::read();
    let doc = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let order = stated_order(&doc).unwrap_or_else(|e| panic!("{e}"));
    let found = order_violations(&order, &krate.top_level(), &krate.modules, &krate.imports());
    assert!(
        found.is_empty(),
        "the module order stated in ARCHITECTURE.md, bottom to top, is {order:?}; \
         a module imports only modules listed before it:\n{}",
        found.join("\n")
    );
}

/// The check itself: a module left out of the list, and an import from
/// above, are each named with the file, the item and both places.
#[test]
fn the_order_check_names_a_missing_module_and_an_import_from_above() {
    let doc = "# A\n\n## Modules, bottom to top\n\n1. `src/error.rs`: errors.\n\n    \
               **Architecture Invariant:** none.\n2. `src/output/`: files.\n3. `src/main.rs`\n\n\
               ## Invariants\n\n1. `src/scene/` is not in the order.\n";
    let order = stated_order(doc).unwrap();
    assert_eq!(order, ["error", "output", "src/main.rs"]);
    let top_level: BTreeSet<String> = ["error", "output", "scene"].map(String::from).into();
    let files: BTreeMap<String, (String, String)> = [
        ("error", "src/error.rs"),
        ("output::files", "src/output/files.rs"),
        ("scene", "src/scene/mod.rs"),
    ]
    .map(|(m, f)| (m.to_owned(), (f.to_owned(), String::new())))
    .into();
    let imports: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = [
        (
            "error",
            "output::files",
            "crate::output::files::atomic_write",
        ),
        ("output::files", "error", "crate::error::Error"),
    ]
    .map(|(m, t, p)| (m.to_owned(), [(t.to_owned(), [p.to_owned()].into())].into()))
    .into();
    let found = order_violations(&order, &top_level, &files, &imports);
    assert_eq!(found.len(), 2, "{found:#?}");
    assert_eq!(
        found[0],
        "src/scene/mod.rs is the top-level module `scene`, which the order in \
         ARCHITECTURE.md (`## Modules, bottom to top`) does not list"
    );
    assert_eq!(
        found[1],
        "src/error.rs imports `crate::output::files::atomic_write` (defined in \
         output::files): `error` is 1 in the module order, `output` is 2 (above it)"
    );
    let unnumbered = doc.replace("2. `src/output/`", "3. `src/output/`");
    assert!(stated_order(&unnumbered)
        .unwrap_err()
        .contains("numbered 2"));
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let krate = Crate::read();
    let edges = krate.edges();
    // The reader sees real edges: the backend uses the method, the method
    // never the backend.
    assert!(
        edges["backend::cpu"].contains("method::lane::driver"),
        "{:?}",
        edges["backend::cpu"]
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
