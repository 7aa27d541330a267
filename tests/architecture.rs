//! The layout rules a newcomer relies on, checked on the crate's own source: no import circles
//! between files, no file over 800 lines and no function over 120 lines outside its tests, and
//! the body's state implemented in two files only.
//!
//! An import is a `crate::`, `super::` or `self::` path in a file's code (comments and its
//! `#[cfg(test)] mod tests` left out); it points at the file of the longest module prefix of
//! the path. A module in a folder (`core/impulses/`, `plugin/`) is one room: its `mod.rs`
//! reaches every file in it (a parent-child pair counts as an import both ways, so a file
//! that imports the folder's module and is imported by one of its files closes a circle). The
//! two umbrella folders, `src/` and `src/core/`, are not rooms: their `lib.rs` and `mod.rs`
//! only declare and re-export.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Most lines a source file may have outside its tests.
const MAX_LINES: usize = 800;

/// Most lines a function may have, from its `fn` line to its closing brace, outside tests.
const MAX_FN_LINES: usize = 120;

/// Every `.rs` file under `dir`, in path order.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module path of a file under `src`: `lib.rs` is `[]`, `a/mod.rs` and `a.rs` are `[a]`.
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = relative
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// A file's code: without comments and without its `#[cfg(test)] mod tests`.
fn code(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(end) => &text[..end],
        None => text,
    };
    text.lines()
        .map(|line| line.find("//").map_or(line, |at| &line[..at]))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The paths in `code` that start with `crate`, `super` or `self`, as segments; a group
/// (`super::{a::B, c}`) gives one path per item.
fn paths(code: &str) -> Vec<Vec<String>> {
    let bytes = code.as_bytes();
    let is_ident = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let starts = ["crate::", "super::", "self::"]
            .iter()
            .any(|p| code[i..].starts_with(p))
            && (i == 0 || !is_ident(bytes[i - 1]));
        if !starts {
            i += 1;
            continue;
        }
        let (path, end) = read_path(code, i);
        out.extend(path);
        i = end;
    }
    out
}

/// Reads the path starting at `start`: its expansions (several for a group) and where it ends.
fn read_path(code: &str, start: usize) -> (Vec<Vec<String>>, usize) {
    let bytes = code.as_bytes();
    let is_ident = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
    let mut segments = Vec::new();
    let mut i = start;
    loop {
        let begin = i;
        while i < bytes.len() && is_ident(bytes[i]) {
            i += 1;
        }
        segments.push(code[begin..i].to_string());
        if !code[i..].starts_with("::") {
            return (vec![segments], i);
        }
        i += 2;
        if code[i..].starts_with('{') {
            // A group: each item, up to the matching brace.
            let mut depth = 0;
            let mut item_start = i + 1;
            let mut out = Vec::new();
            let mut j = i;
            while j < bytes.len() {
                match bytes[j] {
                    b'{' => depth += 1,
                    b'}' | b',' if depth == 1 => {
                        let item = code[item_start..j].trim();
                        if !item.is_empty() && item != "self" && item != "*" {
                            let (items, _) = read_path(item, 0);
                            for tail in items {
                                let mut path = segments.clone();
                                path.extend(tail.into_iter().filter(|s| !s.is_empty()));
                                out.push(path);
                            }
                        }
                        item_start = j + 1;
                        if bytes[j] == b'}' {
                            out.push(segments.clone());
                            return (out, j + 1);
                        }
                    }
                    b'}' => depth -= 1,
                    _ => {}
                }
                j += 1;
            }
            return (out, j);
        }
        if code[i..].starts_with('*') {
            return (vec![segments], i + 1);
        }
    }
}

/// The file a path used in the module `current` points at: that of its longest prefix that
/// is a module of the crate.
fn resolve<'a>(
    modules: &'a BTreeMap<Vec<String>, PathBuf>,
    current: &[String],
    path: &[String],
) -> Option<&'a PathBuf> {
    let mut base: Vec<String> = match path.first().map(String::as_str) {
        Some("crate") => Vec::new(),
        Some("super") | Some("self") => current.to_vec(),
        _ => return None,
    };
    let mut rest = &path[1..];
    if path[0] == "super" {
        base.pop();
        while rest.first().is_some_and(|s| s == "super") {
            base.pop();
            rest = &rest[1..];
        }
    }
    let mut found = modules.get(&base);
    for segment in rest {
        base.push(segment.clone());
        if let Some(file) = modules.get(&base) {
            found = Some(file);
        }
    }
    found
}

/// Whether `file` is a module compiled for tests only: declared under `#[cfg(test)]` in its
/// parent (as `tests.rs` files and the passes' plain oracle are).
fn test_only(src: &Path, file: &Path) -> bool {
    let path = module_path(src, file);
    let Some(name) = path.last() else {
        return false;
    };
    let parent = &path[..path.len() - 1];
    let folder = parent.iter().fold(src.to_path_buf(), |f, p| f.join(p));
    let parent_file = if parent.is_empty() {
        src.join("lib.rs")
    } else if folder.join("mod.rs").exists() {
        folder.join("mod.rs")
    } else {
        folder.with_extension("rs")
    };
    let text = std::fs::read_to_string(parent_file).unwrap_or_default();
    ["mod", "pub mod", "pub(crate) mod"]
        .iter()
        .any(|m| text.contains(&format!("#[cfg(test)]\n{m} {name};")))
}

/// The room `file` is in: the file itself, or its folder for a module in a folder other than
/// the umbrellas `src/` and `src/core/`.
fn room(src: &Path, file: &Path) -> PathBuf {
    let folder = file.parent().unwrap();
    if folder == src || folder == src.join("core") {
        file.to_path_buf()
    } else {
        folder.to_path_buf()
    }
}

struct Crate {
    src: PathBuf,
    files: Vec<PathBuf>,
    /// Each room's imports (other rooms), by room: a file, or a folder module's folder.
    imports: BTreeMap<PathBuf, Vec<PathBuf>>,
}

fn this_crate() -> Crate {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let modules: BTreeMap<Vec<String>, PathBuf> = files
        .iter()
        .map(|f| (module_path(&src, f), f.clone()))
        .collect();
    let mut imports = BTreeMap::new();
    for file in files.iter().filter(|f| !test_only(&src, f)) {
        let current = module_path(&src, file);
        let code = code(&std::fs::read_to_string(file).unwrap());
        let targets: Vec<PathBuf> = paths(&code)
            .iter()
            .filter_map(|p| resolve(&modules, &current, p))
            .filter(|target| *target != file)
            .cloned()
            .collect();
        let mut targets: Vec<PathBuf> = targets.iter().map(|t| room(&src, t)).collect();
        let here = room(&src, file);
        targets.retain(|t| *t != here);
        imports.entry(here).or_insert_with(Vec::new).extend(targets);
    }
    for targets in imports.values_mut() {
        targets.sort();
        targets.dedup();
    }
    Crate {
        src,
        files,
        imports,
    }
}

/// An import circle through `start`, if there is one: the files in order.
fn circle_through(imports: &BTreeMap<PathBuf, Vec<PathBuf>>, start: &Path) -> Option<Vec<PathBuf>> {
    // Depth-first search for a path from `start`'s imports back to `start`.
    let mut stack: Vec<(PathBuf, usize)> = vec![(start.to_path_buf(), 0)];
    let mut seen = std::collections::BTreeSet::new();
    while let Some((file, next)) = stack.last().cloned() {
        let targets = &imports[&file];
        if next == targets.len() {
            stack.pop();
            continue;
        }
        stack.last_mut().unwrap().1 += 1;
        let target = &targets[next];
        if target == start {
            return Some(stack.iter().map(|(f, _)| f.clone()).collect());
        }
        if seen.insert(target.clone()) {
            stack.push((target.clone(), 0));
        }
    }
    None
}

#[test]
fn no_file_imports_a_file_that_imports_it_back() {
    let krate = this_crate();
    // The check itself sees imports: the body uses the mesh, the plugin the core.
    let sees =
        |from: &str, to: &str| krate.imports[&krate.src.join(from)].contains(&krate.src.join(to));
    assert!(sees("core/body.rs", "core/tet_mesh.rs"));
    assert!(sees("plugin", "core/substep_plan.rs"));
    // A folder module is one room, whichever of its files imports.
    assert!(sees("core/impulses", "core/lanes.rs"));
    assert!(sees("core/body.rs", "core/impulses"));
    // Modules compiled for tests only import nothing here.
    assert!(test_only(
        &krate.src,
        &krate.src.join("core/impulses/tests.rs")
    ));
    assert!(!test_only(
        &krate.src,
        &krate.src.join("core/impulses/ring.rs")
    ));
    for file in krate.imports.keys() {
        if let Some(circle) = circle_through(&krate.imports, file) {
            let names: Vec<_> = circle
                .iter()
                .map(|f| f.strip_prefix(&krate.src).unwrap().display().to_string())
                .collect();
            panic!("import circle: {} -> back", names.join(" -> "));
        }
    }
}

#[test]
fn the_circle_check_finds_a_circle() {
    let mut imports = BTreeMap::new();
    let (a, b, c) = (PathBuf::from("a"), PathBuf::from("b"), PathBuf::from("c"));
    imports.insert(a.clone(), vec![b.clone()]);
    imports.insert(b.clone(), vec![c.clone()]);
    imports.insert(c.clone(), vec![a.clone()]);
    assert_eq!(circle_through(&imports, &a), Some(vec![a.clone(), b, c]));
    imports.insert(PathBuf::from("c"), vec![]);
    assert_eq!(circle_through(&imports, &a), None);
    let paths = paths("use super::{body::SoftBodyState, lanes::{LANES, Point4}};");
    assert!(paths.contains(&vec!["super".into(), "body".into(), "SoftBodyState".into()]));
    assert!(paths.contains(&vec!["super".into(), "lanes".into(), "Point4".into()]));
}

#[test]
fn no_file_is_over_800_lines_outside_its_tests() {
    let krate = this_crate();
    let long: Vec<String> = krate
        .files
        .iter()
        .filter(|f| f.file_name().is_some_and(|n| n != "tests.rs"))
        .filter_map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            let lines = match text.find("#[cfg(test)]\nmod tests") {
                Some(end) => text[..end].lines().count(),
                None => text.lines().count(),
            };
            (lines > MAX_LINES).then(|| format!("{} ({lines} lines)", f.display()))
        })
        .collect();
    assert!(long.is_empty(), "files over {MAX_LINES} lines: {long:?}");
}

/// The braces of a line of code, in order, outside string and character literals.
fn braces(line: &str) -> Vec<char> {
    let chars: Vec<char> = line.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut in_string) = (0, false);
    while i < chars.len() {
        let c = chars[i];
        if in_string {
            match c {
                '\\' => i += 1,
                '"' => in_string = false,
                _ => {}
            }
        } else if c == '"' {
            in_string = true;
        } else if c == '\'' && chars.get(i + 2) == Some(&'\'') {
            i += 2;
        } else if c == '\'' && chars.get(i + 1) == Some(&'\\') {
            // An escaped character literal: on to its closing quote.
            i += 2;
            while i < chars.len() && chars[i] != '\'' {
                i += 1;
            }
        } else if c == '{' || c == '}' {
            out.push(c);
        }
        i += 1;
    }
    out
}

/// The functions in `code` (a file's code, as [`code`] gives it) with their length in lines,
/// from the `fn` line to the closing brace; declarations without a body are left out.
fn function_lengths(code: &str) -> Vec<(String, usize)> {
    let lines: Vec<&str> = code.lines().collect();
    let mut found = Vec::new();
    for (start, line) in lines.iter().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some(at) = words.iter().position(|&w| w == "fn") else {
            continue;
        };
        let qualifiers = [
            "pub",
            "pub(crate)",
            "pub(super)",
            "const",
            "unsafe",
            "async",
        ];
        if !words[..at].iter().all(|w| qualifiers.contains(w)) {
            continue;
        }
        let name = words
            .get(at + 1)
            .map_or("", |w| w.split(['(', '<']).next().unwrap_or(""));
        let mut depth = 0i32;
        for (end, line) in lines.iter().enumerate().skip(start) {
            let opened = depth > 0;
            for brace in braces(line) {
                depth += if brace == '{' { 1 } else { -1 };
            }
            if (opened || line.contains('{')) && depth == 0 {
                found.push((name.to_string(), end - start + 1));
                break;
            }
            if !opened && depth == 0 && line.trim_end().ends_with(';') {
                break;
            }
        }
    }
    found
}

#[test]
fn the_function_length_check_measures_functions() {
    let mut code = String::from("pub(crate) fn long(x: u32) -> u32 {\n    let s = \"{\";\n");
    code += &"    let c = '{';\n".repeat(MAX_FN_LINES);
    code += "    x\n}\n\nfn short() {}\n\ntrait T {\n    fn declared(&self);\n}\n";
    assert_eq!(
        function_lengths(&code),
        vec![
            ("long".to_string(), MAX_FN_LINES + 4),
            ("short".to_string(), 1)
        ]
    );
}

#[test]
fn no_function_is_over_120_lines_outside_its_tests() {
    let krate = this_crate();
    let mut long = Vec::new();
    for file in &krate.files {
        if file.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let code = code(&std::fs::read_to_string(file).unwrap());
        for (name, lines) in function_lengths(&code) {
            if lines > MAX_FN_LINES {
                let file = file.strip_prefix(&krate.src).unwrap().display().to_string();
                long.push(format!("{file}: {name} ({lines} lines)"));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {MAX_FN_LINES} lines: {long:?}"
    );
}

/// The files besides `core/body.rs` and the step's (`core/substep.rs`) that implement
/// `SoftBodyState`: none (but modules compiled for tests only, as the passes' plain oracle).
/// Each concept's file works on its own state, which the body lends it.
#[test]
fn the_body_state_is_implemented_in_the_body_and_the_step_only() {
    let krate = this_crate();
    let allowed = [
        krate.src.join("core/body.rs"),
        krate.src.join("core/substep.rs"),
    ];
    let others: Vec<String> = krate
        .files
        .iter()
        .filter(|f| !allowed.contains(f) && !test_only(&krate.src, f))
        .filter(|f| {
            let code = code(&std::fs::read_to_string(f).unwrap());
            code.contains("impl SoftBodyState") || code.contains("for SoftBodyState")
        })
        .map(|f| f.strip_prefix(&krate.src).unwrap().display().to_string())
        .collect();
    assert!(others.is_empty(), "impl SoftBodyState in {others:?}");
}

/// Every public item reachable from the crate root has its doc comment: the crate denies
/// `missing_docs`, so an undocumented one does not build.
#[test]
fn every_public_item_is_documented() {
    let krate = this_crate();
    let lib = std::fs::read_to_string(krate.src.join("lib.rs")).unwrap();
    assert!(lib.contains("#![deny(missing_docs)]"));
}
