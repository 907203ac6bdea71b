//! The shape of the code (issue 33), checked on every crate's sources:
//! imports point one way (no cycle between source files, of any length),
//! no source file is over 800 lines but for its tests, and every module
//! says in a `//!` header what it owns.
//!
//! The import graph is read from the text, as a newcomer would: every
//! `use` tree and every `crate::`/`super::`/`self::` path (and a path
//! through a child module) is an edge from the file to the file of the
//! module it names; a name a module only re-exports (`pub use`) leads on
//! to the module that defines it. `#[cfg(test)]` modules are left out
//! (tests may look anywhere). Cycles are the strongly connected
//! components of that graph (Tarjan).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates' source roots, from the workspace root.
const ROOTS: [&str; 4] = [
    "src",
    "crates/zwidth-core/src",
    "crates/zwidth-dsp/src",
    "crates/zwidth-ffi/src",
];

/// Lines a source file may hold, its `#[cfg(test)]` modules left out.
const MAX_LINES: usize = 800;

type ModPath = Vec<String>;

/// One crate: its modules' files and what each refers to.
struct Crate {
    files: BTreeMap<ModPath, PathBuf>,
    /// Module → its source with comments, strings and test modules removed.
    code: BTreeMap<ModPath, String>,
}

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            walk(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `zwidth/search.rs` → [zwidth, search]; `a/mod.rs` → [a]; `lib.rs` → [].
fn module_of(root: &Path, file: &Path) -> ModPath {
    let rel = file.strip_prefix(root).unwrap().with_extension("");
    let mut m: ModPath = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if m.last().is_some_and(|l| l == "mod") || m == ["lib"] || m == ["main"] {
        m.pop();
    }
    m
}

impl Crate {
    fn read(root: &Path) -> Self {
        let mut paths = vec![];
        walk(root, &mut paths);
        let mut files = BTreeMap::new();
        let mut code = BTreeMap::new();
        for p in paths {
            // The binary beside a library is a crate of its own.
            if p == root.join("main.rs") && root.join("lib.rs").exists() {
                continue;
            }
            // Test modules in files of their own (`tests.rs`,
            // `friction_tests.rs`, `#[path]`-included) are tests.
            let stem = p.file_stem().unwrap().to_string_lossy();
            if stem == "tests" || stem.ends_with("_tests") {
                continue;
            }
            let m = module_of(root, &p);
            code.insert(m.clone(), code_of(&std::fs::read_to_string(&p).unwrap()));
            files.insert(m, p);
        }
        Crate { files, code }
    }

    /// The longest prefix of `full` that is a module of this crate.
    fn module_at(&self, full: &[String]) -> (ModPath, Vec<String>) {
        for i in (0..=full.len()).rev() {
            if self.files.contains_key(&full[..i]) {
                return (full[..i].to_vec(), full[i..].to_vec());
            }
        }
        (vec![], full.to_vec())
    }

    /// Absolute module path of `path` written in module `me`, if it is a
    /// path into this crate.
    fn absolute(&self, me: &ModPath, path: &[String]) -> Option<Vec<String>> {
        let mut base = me.clone();
        let mut rest = path;
        match path.first()?.as_str() {
            "crate" => {
                base.clear();
                rest = &path[1..];
            }
            "super" | "self" => {
                while let Some(s) = rest.first() {
                    match s.as_str() {
                        "super" => {
                            base.pop()?;
                        }
                        "self" => {}
                        _ => break,
                    }
                    rest = &rest[1..];
                }
            }
            first => {
                let mut child = me.clone();
                child.push(first.to_string());
                if !self.files.contains_key(&child) {
                    return None;
                }
            }
        }
        base.extend(rest.iter().cloned());
        Some(base)
    }

    /// The module defining what `full` names: re-exports followed; None
    /// when it is another crate's (a re-export of a dependency).
    fn defining(&self, full: &[String], depth: usize) -> Option<ModPath> {
        let (m, rest) = self.module_at(full);
        if depth < 8 {
            if let Some(name) = rest.first() {
                for (exported, target) in reexports(&self.code[&m]) {
                    if &exported == name {
                        let abs = self.absolute(&m, &target)?;
                        return self.defining(&abs, depth + 1);
                    }
                }
            }
        }
        Some(m)
    }

    /// The import graph between this crate's files. With
    /// `ZWIDTH_IMPORTS_OF=a::b`, the paths of that module that make its
    /// edges are printed (to see which import to move).
    fn graph(&self) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
        let explain = std::env::var("ZWIDTH_IMPORTS_OF").unwrap_or_default();
        let mut g = BTreeMap::new();
        for (me, code) in &self.code {
            let mut to = BTreeSet::new();
            for path in paths(code) {
                let Some(d) = self
                    .absolute(me, &path)
                    .and_then(|abs| self.defining(&abs, 0))
                else {
                    continue;
                };
                {
                    if &d != me {
                        if !explain.is_empty() && me.join("::") == explain {
                            eprintln!("{explain}: {} -> {}", path.join("::"), name("", &d));
                        }
                        to.insert(d);
                    }
                }
            }
            g.insert(me.clone(), to);
        }
        g
    }
}

/// Source with comments, string and char literals blanked (their text
/// could look like paths or braces): the same bytes at the same places,
/// newlines kept, so positions and line numbers are the source's.
fn mask(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = String::with_capacity(s.len());
    let blank = |out: &mut String, text: &str| {
        for c in text.chars() {
            if c == '\n' {
                out.push('\n');
            } else {
                out.push_str(&" ".repeat(c.len_utf8()));
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        let rest = &s[i..];
        let len = if rest.starts_with("//") {
            rest.find('\n').unwrap_or(rest.len())
        } else if rest.starts_with("/*") {
            let (mut depth, mut j) = (0, 0);
            while j < rest.len() {
                if rest[j..].starts_with("/*") {
                    depth += 1;
                    j += 2;
                } else if rest[j..].starts_with("*/") {
                    depth -= 1;
                    j += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    j += rest[j..].chars().next().map_or(1, char::len_utf8);
                }
            }
            j
        } else if let Some(hashes) = raw_string_start(rest) {
            // r"…", r#"…"#, br#"…"#
            let open = rest.find('"').unwrap();
            let close = format!("\"{}", "#".repeat(hashes));
            rest[open + 1..]
                .find(&close)
                .map_or(rest.len(), |e| open + 1 + e + close.len())
        } else if b[i] == b'"' {
            let mut j = 1;
            while j < rest.len() && rest.as_bytes()[j] != b'"' {
                j += if rest.as_bytes()[j] == b'\\' { 2 } else { 1 };
            }
            (j + 1).min(rest.len())
        } else if b[i] == b'\'' && char_literal_len(rest).is_some() {
            char_literal_len(rest).unwrap()
        } else {
            let c = rest.chars().next().unwrap();
            out.push(c);
            i += c.len_utf8();
            continue;
        };
        blank(&mut out, &rest[..len]);
        i += len;
    }
    out
}

/// `r"`, `r#"`, `br##"` …: the number of hashes.
fn raw_string_start(s: &str) -> Option<usize> {
    let t = s.strip_prefix('b').unwrap_or(s).strip_prefix('r')?;
    let hashes = t.len() - t.trim_start_matches('#').len();
    t[hashes..].starts_with('"').then_some(hashes)
}

/// The length of a char literal at the start of `s` ('x', '\n', '\''),
/// None for a lifetime.
fn char_literal_len(s: &str) -> Option<usize> {
    let t = &s[1..];
    if let Some(esc) = t.strip_prefix('\\') {
        let end = esc.find('\'')?;
        return (end <= 10).then_some(end + 3);
    }
    let c = t.chars().next()?;
    t[c.len_utf8()..]
        .starts_with('\'')
        .then_some(c.len_utf8() + 2)
}

/// Where the `#[cfg(test)] mod … { … }` blocks of `masked` (see [`mask`])
/// are: byte ranges. `#[cfg(test)]` on a single item stays (it is small).
fn test_ranges(masked: &str) -> Vec<std::ops::Range<usize>> {
    const ATTR: &str = "#[cfg(test)]";
    let mut out = vec![];
    let mut from = 0;
    while let Some(at) = masked[from..].find(ATTR).map(|a| from + a) {
        from = at + ATTR.len();
        // Other attributes may sit between it and the module.
        let mut rest = masked[from..].trim_start();
        while rest.starts_with("#[") {
            let close = rest.find(']').map_or(rest.len(), |c| c + 1);
            rest = rest[close..].trim_start();
        }
        if !(rest.starts_with("mod ") || rest.starts_with("pub mod ")) {
            continue;
        }
        let Some(open) = masked[from..].find(['{', ';']).map(|o| from + o) else {
            break;
        };
        if masked.as_bytes()[open] == b';' {
            // `mod tests;`: the file is skipped on its own (a `tests.rs`).
            out.push(at..open + 1);
            continue;
        }
        let mut depth = 0;
        let mut end = masked.len();
        for (k, c) in masked[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + k + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        out.push(at..end);
        from = end;
    }
    out
}

/// `s` without the byte `ranges` (in order, not overlapping).
fn without(s: &str, ranges: &[std::ops::Range<usize>]) -> String {
    let mut out = String::with_capacity(s.len());
    let mut at = 0;
    for r in ranges {
        out.push_str(&s[at..r.start]);
        at = r.end;
    }
    out.push_str(&s[at..]);
    out
}

/// Code as the import graph reads it: masked, its test modules left out.
fn code_of(source: &str) -> String {
    let masked = mask(source);
    without(&masked, &test_ranges(&masked))
}

/// The source's lines but for its test modules.
fn lines_but_tests(source: &str) -> usize {
    without(source, &test_ranges(&mask(source))).lines().count()
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Every path of two or more segments in `code`, and every path a `use`
/// tree names (expanded).
fn paths(code: &str) -> Vec<Vec<String>> {
    let mut out = vec![];
    for tree in use_trees(code) {
        out.extend(
            expand(&tree)
                .into_iter()
                .map(|p| p.iter().map(|s| plain(s).to_string()).collect()),
        );
    }
    // The `use` declarations were read above; the scan reads the rest.
    let code = &without_uses(code);
    let chars: Vec<(usize, char)> = code.char_indices().collect();
    let mut k = 0;
    while k < chars.len() {
        let (i, c) = chars[k];
        let starts = is_ident(c)
            && !c.is_ascii_digit()
            && (k == 0 || {
                let p = chars[k - 1].1;
                !is_ident(p) && p != ':'
            });
        if !starts {
            k += 1;
            continue;
        }
        let mut segs = vec![];
        let mut j = i;
        loop {
            let seg: String = code[j..].chars().take_while(|&c| is_ident(c)).collect();
            if seg.is_empty() {
                break;
            }
            j += seg.len();
            segs.push(seg);
            if code[j..].starts_with("::") && code[j + 2..].starts_with(|c: char| is_ident(c)) {
                j += 2;
            } else {
                break;
            }
        }
        if segs.len() >= 2 {
            out.push(segs);
        }
        while k < chars.len() && chars[k].0 < j {
            k += 1;
        }
    }
    out
}

/// `code` with its `use` declarations blanked.
fn without_uses(code: &str) -> String {
    let mut out = code.to_string();
    for tree_at in use_positions(code) {
        let end = code[tree_at..]
            .find(';')
            .map_or(code.len(), |e| tree_at + e);
        out.replace_range(tree_at..end, &" ".repeat(end - tree_at));
    }
    out
}

/// Where each `use` declaration's tree starts.
fn use_positions(code: &str) -> Vec<usize> {
    let mut out = vec![];
    let mut from = 0;
    while let Some(at) = code[from..].find("use ") {
        let at = from + at;
        from = at + 4;
        if at == 0 || !is_ident(code[..at].chars().last().unwrap()) {
            out.push(from);
        }
    }
    out
}

/// The trees of every `use` declaration (`pub use a::{b, c::d};` → `a::{b, c::d}`).
fn use_trees(code: &str) -> Vec<String> {
    use_positions(code)
        .into_iter()
        .filter_map(|at| {
            code[at..]
                .find(';')
                .map(|end| normalize(&code[at..at + end]))
        })
        .collect()
}

/// `a::{b, c::{d, e@f}}` (a `use` tree as [`normalize`] writes it) →
/// [a, b], [a, c, d], [a, c, e@f]: a renamed last segment keeps its new
/// name after `@`.
fn expand(tree: &str) -> Vec<Vec<String>> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else {
        return vec![tree
            .split("::")
            .filter(|s| !s.is_empty() && *s != "*")
            .map(str::to_string)
            .collect()];
    };
    let prefix = tree[..open].trim_end_matches("::");
    let body = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
    let mut items = vec![];
    let (mut depth, mut cur) = (0, String::new());
    for c in body.chars() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            _ => {}
        }
        if c == ',' && depth == 0 {
            items.push(std::mem::take(&mut cur));
        } else {
            cur.push(c);
        }
    }
    items.push(cur);
    let head: Vec<String> = prefix
        .split("::")
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect();
    let mut out = vec![];
    for it in items.iter().filter(|i| !i.trim().is_empty()) {
        for tail in expand(it) {
            let mut p = head.clone();
            p.extend(tail.into_iter().filter(|s| s != "self"));
            out.push(p);
        }
    }
    out
}

/// A `use` tree without whitespace, ` as ` written `@`.
fn normalize(tree: &str) -> String {
    tree.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace(" as ", "@")
        .replace(' ', "")
}

/// A path segment without its rename.
fn plain(seg: &str) -> &str {
    seg.split('@').next().unwrap_or(seg)
}

/// `pub use a::B;` and `pub use a::{B, C as D};` of a module: (name, path).
fn reexports(code: &str) -> Vec<(String, Vec<String>)> {
    let mut out = vec![];
    for (k, _) in code.match_indices("pub") {
        let rest = &code[k..];
        let rest = rest
            .strip_prefix("pub(crate)")
            .or_else(|| rest.strip_prefix("pub(super)"))
            .or_else(|| rest.strip_prefix("pub"))
            .unwrap();
        let Some(tree) = rest.trim_start().strip_prefix("use ") else {
            continue;
        };
        let tree = normalize(&tree[..tree.find(';').unwrap_or(tree.len())]);
        for p in expand(&tree) {
            if let Some(last) = p.last() {
                let name = last.rsplit('@').next().unwrap_or(last).to_string();
                let path = p.iter().map(|s| plain(s).to_string()).collect();
                out.push((name, path));
            }
        }
    }
    out
}

/// Tarjan's strongly connected components with more than one file.
fn cycles(g: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<Vec<ModPath>> {
    struct T<'a> {
        g: &'a BTreeMap<ModPath, BTreeSet<ModPath>>,
        index: BTreeMap<&'a ModPath, usize>,
        low: BTreeMap<&'a ModPath, usize>,
        stack: Vec<&'a ModPath>,
        on: BTreeSet<&'a ModPath>,
        out: Vec<Vec<ModPath>>,
    }
    impl<'a> T<'a> {
        fn visit(&mut self, n: &'a ModPath) {
            let i = self.index.len();
            self.index.insert(n, i);
            self.low.insert(n, i);
            self.stack.push(n);
            self.on.insert(n);
            for w in self.g.get(n).into_iter().flatten() {
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let l = self.low[w].min(self.low[n]);
                    self.low.insert(n, l);
                } else if self.on.contains(w) {
                    let l = self.index[w].min(self.low[n]);
                    self.low.insert(n, l);
                }
            }
            if self.low[n] == self.index[n] {
                let mut comp = vec![];
                loop {
                    let w = self.stack.pop().unwrap();
                    self.on.remove(w);
                    comp.push(w.clone());
                    if w == n {
                        break;
                    }
                }
                if comp.len() > 1 {
                    comp.sort();
                    self.out.push(comp);
                }
            }
        }
    }
    let mut t = T {
        g,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: vec![],
        on: BTreeSet::new(),
        out: vec![],
    };
    for n in g.keys() {
        if !t.index.contains_key(n) {
            t.visit(n);
        }
    }
    t.out
}

fn name(root: &str, m: &ModPath) -> String {
    let m = if m.is_empty() {
        "crate".into()
    } else {
        m.join("::")
    };
    if root.is_empty() {
        m
    } else {
        format!("{root}:{m}")
    }
}

/// Every import cycle, as `root:a::b -> root:c …` lines.
fn all_cycles() -> Vec<String> {
    let mut out = vec![];
    for root in ROOTS {
        let c = Crate::read(&workspace().join(root));
        let g = c.graph();
        for comp in cycles(&g) {
            // The imports inside the cycle: the ones to remove.
            let mut edges = vec![];
            for a in &comp {
                for b in g[a].iter().filter(|b| comp.contains(b)) {
                    edges.push(format!("{} -> {}", name(root, a), name("", b)));
                }
            }
            out.push(edges.join(", "));
        }
    }
    out
}

#[test]
fn no_import_cycle_between_source_files() {
    let found = all_cycles();
    assert!(
        found.is_empty(),
        "{} import cycles (files that import each other, directly or through others):\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn no_source_file_is_over_800_lines_but_for_its_tests() {
    let mut long = vec![];
    for root in ROOTS {
        let c = Crate::read(&workspace().join(root));
        for (m, file) in &c.files {
            let text = std::fs::read_to_string(file).unwrap();
            let lines = lines_but_tests(&text);
            if lines > MAX_LINES {
                long.push(format!("{} ({lines} lines)", name(root, m)));
            }
        }
    }
    assert!(
        long.is_empty(),
        "over {MAX_LINES} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn every_module_says_what_it_owns() {
    let mut silent = vec![];
    for root in ROOTS {
        let c = Crate::read(&workspace().join(root));
        for (m, file) in &c.files {
            let text = std::fs::read_to_string(file).unwrap();
            if !text.trim_start().starts_with("//!") {
                silent.push(name(root, m));
            }
        }
    }
    assert!(silent.is_empty(), "no `//!` header:\n{}", silent.join("\n"));
}

/// The checker itself, on small sources with a known answer.
mod checker {
    use super::*;

    fn g(edges: &[(&str, &str)]) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
        let mut g: BTreeMap<ModPath, BTreeSet<ModPath>> = BTreeMap::new();
        for (a, b) in edges {
            g.entry(vec![a.to_string()])
                .or_default()
                .insert(vec![b.to_string()]);
            g.entry(vec![b.to_string()]).or_default();
        }
        g
    }

    #[test]
    fn a_cycle_of_three_is_found_and_a_chain_is_not() {
        let c = cycles(&g(&[("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")]));
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].len(), 3);
        assert!(cycles(&g(&[("a", "b"), ("b", "c"), ("a", "c")])).is_empty());
    }

    #[test]
    fn use_trees_expand_to_their_paths() {
        assert_eq!(
            expand(&normalize("crate::a::{b, c::{d, e as f}, self}")),
            [
                vec!["crate", "a", "b"],
                vec!["crate", "a", "c", "d"],
                vec!["crate", "a", "c", "e@f"],
                vec!["crate", "a"],
            ]
        );
        assert_eq!(
            reexports("pub use self::x::{Y, Z as W};"),
            [
                (
                    "Y".to_string(),
                    vec!["self".to_string(), "x".into(), "Y".into()]
                ),
                (
                    "W".to_string(),
                    vec!["self".to_string(), "x".into(), "Z".into()]
                ),
            ]
        );
    }

    #[test]
    fn strings_comments_and_tests_are_not_code() {
        let src = "let a = \"crate::x { \"; // super::y {\n/* self::z\n */ let c = '\"'; let d = '{'; let r = r#\"crate::w\"#; fn f<'a>() {}";
        let m = mask(src);
        assert_eq!(
            (m.len(), m.lines().count()),
            (src.len(), src.lines().count())
        );
        assert!(
            !m.contains("crate::") && !m.contains("super::") && !m.contains("self::"),
            "{m}"
        );
        assert!(m.contains("<'a>") && !m.contains("'{'"), "{m}");
        let t = "use crate::a;\n#[cfg(test)]\n#[allow(x)]\nmod tests {\n use crate::b; let s = \"}\"; { }\n}\nfn g() {}";
        let code = code_of(t);
        assert!(
            code.contains("crate::a") && !code.contains("crate::b") && code.contains("fn g"),
            "{code}"
        );
        assert_eq!(lines_but_tests(t), 3, "{code}");
    }

    /// A small crate on disk: a cycle through a re-export is found (the
    /// re-export leads to the defining file), and the same crate with the
    /// import pointing one way has none.
    #[test]
    fn a_cycle_through_a_reexport_is_found_in_files() {
        let dir = std::env::temp_dir().join(format!("zwidth-arch-{}", std::process::id()));
        let write = |files: &[(&str, &str)]| {
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            for (name, text) in files {
                std::fs::write(dir.join(name), text).unwrap();
            }
            let c = Crate::read(&dir);
            cycles(&c.graph())
        };
        let lib = ("lib.rs", "//! l\nmod a;\nmod b;\npub use a::X;\n");
        let found = write(&[
            lib,
            ("a.rs", "//! a\nuse crate::b::Y;\npub struct X(Y);\n"),
            (
                "b.rs",
                "//! b\npub struct Y;\nfn f() -> crate::X { todo!() }\n",
            ),
        ]);
        assert_eq!(found, [vec![vec!["a".to_string()], vec!["b".to_string()]]]);
        let none = write(&[
            lib,
            ("a.rs", "//! a\nuse crate::b::Y;\npub struct X(Y);\n"),
            (
                "b.rs",
                "//! b\npub struct Y;\n#[cfg(test)]\nmod tests { use crate::X; }\n",
            ),
        ]);
        assert!(none.is_empty(), "{none:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
