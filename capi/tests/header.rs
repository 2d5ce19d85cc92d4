//! The hand-written header must match the Rust exports: every `extern "C"`
//! function is declared with the same name and parameter count, every
//! declared `capsule_mpc_*` function exists, and every `CAPSULE_MPC_*`
//! constant has the same value on both sides.

use std::collections::BTreeMap;

fn read(rel: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

/// Strips `//` and `/* */` comments (good enough for these two files).
fn strip_comments(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    loop {
        let line = rest.find("//");
        let block = rest.find("/*");
        match (line, block) {
            (None, None) => {
                out.push_str(rest);
                return out;
            }
            (Some(l), None) => {
                out.push_str(&rest[..l]);
                rest = rest[l..].find('\n').map_or("", |e| &rest[l + e..]);
            }
            (Some(l), Some(b)) if l < b => {
                out.push_str(&rest[..l]);
                rest = rest[l..].find('\n').map_or("", |e| &rest[l + e..]);
            }
            (_, Some(b)) => {
                out.push_str(&rest[..b]);
                let end = rest[b..].find("*/").expect("unterminated comment");
                rest = &rest[b + end + 2..];
            }
        }
    }
}

/// Counts the parameters of a parameter list text (without the parens).
fn param_count(params: &str) -> usize {
    let p = params.trim();
    if p.is_empty() || p == "void" {
        0
    } else {
        p.trim_end_matches(',').split(',').count()
    }
}

/// Text between the `(` at `open` and its matching `)`.
fn paren_body(s: &str, open: usize) -> &str {
    let mut depth = 0;
    for (i, c) in s[open..].char_indices() {
        match c {
            '(' => depth += 1,
            ')' => {
                depth -= 1;
                if depth == 0 {
                    return &s[open + 1..open + i];
                }
            }
            _ => {}
        }
    }
    panic!("unbalanced parentheses");
}

fn rust_functions(src: &str) -> BTreeMap<String, usize> {
    let mut fns = BTreeMap::new();
    let key = "extern \"C\" fn ";
    let mut at = 0;
    while let Some(i) = src[at..].find(key) {
        let start = at + i + key.len();
        let open = start + src[start..].find('(').unwrap();
        let name = src[start..open].trim().to_string();
        let prefix = &src[src[..at + i].rfind('\n').map_or(0, |n| n + 1)..at + i];
        assert!(
            prefix.trim_start().starts_with("pub"),
            "{name}: extern \"C\" fn must be pub"
        );
        fns.insert(name, param_count(paren_body(src, open)));
        at = open;
    }
    fns
}

fn c_functions(h: &str) -> BTreeMap<String, usize> {
    let mut fns = BTreeMap::new();
    let mut at = 0;
    while let Some(i) = h[at..].find("capsule_mpc_") {
        let start = at + i;
        let name_len = h[start..]
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap();
        let name = &h[start..start + name_len];
        let after = start + name_len;
        if h[after..].starts_with('(') {
            fns.insert(name.to_string(), param_count(paren_body(h, after)));
        }
        at = after;
    }
    fns
}

fn rust_consts(src: &str) -> BTreeMap<String, i64> {
    let mut out = BTreeMap::new();
    let ours = |name: &str| -> i64 {
        use capsule_mpc_capi::*;
        match name {
            "CAPSULE_MPC_STATUS_OK" => CAPSULE_MPC_STATUS_OK.into(),
            "CAPSULE_MPC_STATUS_FALLBACK" => CAPSULE_MPC_STATUS_FALLBACK.into(),
            "CAPSULE_MPC_STATUS_ITERATION_LIMIT" => CAPSULE_MPC_STATUS_ITERATION_LIMIT.into(),
            "CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED" => {
                CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED.into()
            }
            "CAPSULE_MPC_STATUS_MEASUREMENT_LOST" => CAPSULE_MPC_STATUS_MEASUREMENT_LOST.into(),
            "CAPSULE_MPC_STATUS_NO_TARGET" => CAPSULE_MPC_STATUS_NO_TARGET.into(),
            "CAPSULE_MPC_STATUS_REACQUIRED" => CAPSULE_MPC_STATUS_REACQUIRED.into(),
            "CAPSULE_MPC_STATUS_ABOVE_ITERATION_MAP" => {
                CAPSULE_MPC_STATUS_ABOVE_ITERATION_MAP.into()
            }
            "CAPSULE_MPC_STATUS_RECOVERING" => CAPSULE_MPC_STATUS_RECOVERING.into(),
            _ => panic!("no evaluator for {name}: add it to tests/header.rs"),
        }
    };
    for line in src.lines() {
        let Some(rest) = line.trim().strip_prefix("pub const CAPSULE_MPC_") else {
            continue;
        };
        let (name, rest) = rest.split_once(':').unwrap();
        let name = format!("CAPSULE_MPC_{}", name.trim());
        let value = rest
            .split_once('=')
            .unwrap()
            .1
            .trim()
            .trim_end_matches(';')
            .trim();
        let v = value.parse::<i64>().unwrap_or_else(|_| ours(&name));
        out.insert(name, v);
    }
    out
}

fn c_consts(h: &str) -> BTreeMap<String, i64> {
    let mut out = BTreeMap::new();
    for line in h.lines() {
        let Some(rest) = line.trim().strip_prefix("#define ") else {
            continue;
        };
        let mut parts = rest.split_whitespace();
        let name = parts.next().unwrap();
        if !name.starts_with("CAPSULE_MPC_") || name == "CAPSULE_MPC_H" {
            continue;
        }
        let value: String = parts.collect::<Vec<_>>().join("");
        let value = value
            .trim_start_matches('(')
            .trim_end_matches(')')
            .trim_end_matches('u');
        let v = value
            .parse::<i64>()
            .unwrap_or_else(|_| panic!("{name}: cannot parse value {value:?}"));
        out.insert(name.to_string(), v);
    }
    out
}

#[test]
fn header_declares_every_export_with_same_arity() {
    let src = strip_comments(&read("src/lib.rs"));
    let h = strip_comments(&read("include/capsule_mpc.h"));
    let rust = rust_functions(&src);
    let c = c_functions(&h);
    assert!(
        rust.len() >= 13,
        "found only {} exports: {rust:?}",
        rust.len()
    );
    assert_eq!(
        rust, c,
        "Rust exports (left) and header declarations (right) differ"
    );
}

#[test]
fn header_constants_match() {
    let src = strip_comments(&read("src/lib.rs"));
    let h = strip_comments(&read("include/capsule_mpc.h"));
    let rust = rust_consts(&src);
    let c = c_consts(&h);
    assert!(rust.contains_key("CAPSULE_MPC_ERR_NOT_INITIALIZED"));
    assert_eq!(
        rust, c,
        "Rust constants (left) and header #defines (right) differ"
    );
}

#[test]
fn every_export_is_no_mangle() {
    let src = strip_comments(&read("src/lib.rs"));
    let exports = src.matches("extern \"C\" fn ").count();
    assert_eq!(src.matches("#[no_mangle]").count(), exports);
}

/// Every "N bytes" (digits grouped by spaces, e.g. "12 760 bytes") that
/// follows the word "workspace" within `window` characters in `text`
/// (whitespace normalized), and every "controller struct N".
#[cfg(not(feature = "three-capsules"))]
fn documented_sizes(text: &str, window: usize) -> (Vec<usize>, Vec<usize>) {
    let flat: String = text.split_whitespace().collect::<Vec<_>>().join(" ");
    let lower = flat.to_lowercase();
    let number_before = |s: &str, end: usize| -> Option<usize> {
        // Digits and single spaces between digit groups, ending at `end`.
        let head = s[..end].trim_end();
        let start = head
            .char_indices()
            .rev()
            .take_while(|(_, c)| c.is_ascii_digit() || *c == ' ')
            .last()
            .map(|(i, _)| i)?;
        let digits: String = head[start..]
            .trim()
            .chars()
            .filter(|c| c.is_ascii_digit())
            .collect();
        digits.parse().ok()
    };
    let mut workspace = Vec::new();
    let mut at = 0;
    while let Some(i) = lower[at..].find("workspace") {
        let from = at + i;
        let until = (from + window).min(lower.len());
        if let Some(b) = lower[from..until].find(" bytes") {
            // Skip "capsule_mpc_workspace_size()` bytes" (no number).
            if let Some(n) = number_before(&flat, from + b) {
                workspace.push(n);
            }
        }
        at = from + "workspace".len();
    }
    let mut controller = Vec::new();
    let key = "controller struct ";
    let mut at = 0;
    while let Some(i) = lower[at..].find(key) {
        let from = at + i + key.len();
        let digits: String = flat[from..]
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == ' ')
            .filter(|c| c.is_ascii_digit())
            .collect();
        controller.push(digits.parse().expect("a number after 'controller struct'"));
        at = from;
    }
    (workspace, controller)
}

/// The workspace sizes the docs quote are the library's: the top-level
/// README, every page of `docs/` (the embedding page's C section, the
/// compute-time page) and the capi README all come from
/// `capsule_mpc_workspace_size()` and the controller's size.
#[test]
#[cfg(not(feature = "three-capsules"))]
fn documented_sizes_are_the_librarys() {
    let size = capsule_mpc_capi::capsule_mpc_workspace_size();
    let controller = core::mem::size_of::<capsule_mpc_runtime::DefaultController>();
    let docs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs");
    let mut pages: Vec<String> = std::fs::read_dir(&docs)
        .unwrap_or_else(|e| panic!("reading {}: {e}", docs.display()))
        .map(|entry| entry.unwrap().file_name().into_string().unwrap())
        .filter(|name| name.ends_with(".md"))
        .map(|name| format!("../docs/{name}"))
        .collect();
    pages.sort();
    pages.extend(["../README.md".to_string(), "README.md".to_string()]);
    let mut found = BTreeMap::new();
    for rel in &pages {
        let (ws, ctl) = documented_sizes(&read(rel), 40);
        for n in &ws {
            assert_eq!(
                *n, size,
                "{rel} quotes a {n}-byte workspace; capsule_mpc_workspace_size() = {size}"
            );
        }
        found.insert(rel.as_str(), ws.len());
        for n in ctl {
            assert_eq!(
                n, controller,
                "{rel} quotes a {n}-byte controller; size_of::<DefaultController>() = {controller}"
            );
        }
    }
    for rel in ["README.md", "../docs/embedding.md"] {
        assert!(
            found[rel] >= 1,
            "expected the workspace size in {rel}: {found:?}"
        );
    }
    assert!(
        found.values().sum::<usize>() >= 3,
        "expected the workspace size in the capi README and the docs: {found:?}"
    );
}
