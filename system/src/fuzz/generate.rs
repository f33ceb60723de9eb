//! Structure-aware generators: documents with the real keys and tags of each format, random
//! nesting, random values (NaN, infinities, huge, negative, wrong types), written out as TOML,
//! YAML, JSON or XML, then perhaps cut short or edited byte by byte.

use embodied_models::rng::Rng;

/// A generic document: what TOML, YAML and JSON files hold.
#[derive(Debug, Clone)]
pub enum Doc {
    /// A mapping, in order (keys may repeat: a junk document).
    Map(Vec<(String, Doc)>),
    /// A sequence.
    Seq(Vec<Doc>),
    /// A float (any, NaN and infinities too).
    Num(f64),
    /// An integer.
    Int(i64),
    /// A string.
    Str(String),
    /// A boolean.
    Bool(bool),
    /// Null (absent in TOML: written as an empty string).
    Null,
}

/// An XML element.
#[derive(Debug, Clone, Default)]
pub struct Elem {
    /// Tag name.
    pub tag: String,
    /// Attributes, in order (names may repeat: a junk document).
    pub attrs: Vec<(String, String)>,
    /// Child elements.
    pub children: Vec<Elem>,
    /// Text before the children.
    pub text: Option<String>,
}

impl Elem {
    /// An element with attributes and no children.
    pub fn new(tag: &str, attrs: Vec<(&str, String)>) -> Self {
        Self { tag: tag.into(), attrs: attrs.into_iter().map(|(k, v)| (k.to_string(), v)).collect(), ..Self::default() }
    }

    /// With these children.
    pub fn with(mut self, children: Vec<Elem>) -> Self {
        self.children = children;
        self
    }
}

/// Numbers at the edges of `f64` and of what a loader checks.
const WILD: [f64; 16] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MAX,
    -f64::MAX,
    0.0,
    -0.0,
    1e-320,
    1e20,
    -1e20,
    -1.0,
    4_294_967_296.0,
    9.007_199_254_740_993e15,
    1e308,
    -3.5,
    1e-9,
];

/// Short strings that break parsers or the checks behind them.
const JUNK_STRINGS: [&str; 16] = [
    "",
    " ",
    "nan",
    "inf",
    "-1e309",
    "é",
    "\u{0}",
    "../../etc/passwd",
    "package://",
    "file:///nonexistent",
    "a b c",
    "1 2",
    "<x>",
    "\"",
    "'",
    "\\",
];

/// The random source of one generated input, and how often a value turns to junk.
pub struct G {
    /// The random numbers.
    rng: std::cell::RefCell<Rng>,
    /// Probability that a value is replaced by junk (a wrong type, a wild number, a wrong length).
    pub junk: f64,
}

impl G {
    /// A generator for one input.
    pub fn new(seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        // Some inputs are almost well formed, some are mostly junk.
        let junk = [0.0, 0.0, 0.002, 0.01, 0.05, 0.2][rng.below(6)];
        Self { rng: std::cell::RefCell::new(rng), junk }
    }

    /// Uniform integer in `[0, n)`.
    pub fn below(&self, n: usize) -> usize {
        self.rng.borrow_mut().below(n)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&self) -> f64 {
        self.rng.borrow_mut().uniform()
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&self, lo: f64, hi: f64) -> f64 {
        self.rng.borrow_mut().range(lo, hi)
    }

    /// 64 random bits.
    pub fn next_u64(&self) -> u64 {
        self.rng.borrow_mut().next_u64()
    }

    /// True with probability `p`.
    pub fn p(&self, p: f64) -> bool {
        self.uniform() < p
    }

    /// True with the junk probability.
    pub fn junky(&self) -> bool {
        let j = self.junk;
        self.p(j)
    }

    /// One of `xs`.
    pub fn pick<T: Clone>(&self, xs: &[T]) -> T {
        xs[self.below(xs.len())].clone()
    }

    /// An integer in `lo..hi`.
    pub fn int(&self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi.saturating_sub(lo).max(1))
    }

    /// A wild number.
    pub fn wild(&self) -> f64 {
        self.pick(&WILD)
    }

    /// A number in `[lo, hi)`, sometimes wild.
    pub fn f(&self, lo: f64, hi: f64) -> f64 {
        if self.junky() || self.p(0.0005) { self.wild() } else { self.range(lo, hi) }
    }

    /// A random string: a junk string or a short identifier.
    pub fn junk_string(&self) -> String {
        if self.p(0.5) {
            self.pick(&JUNK_STRINGS).to_string()
        } else {
            let n = self.int(1, 9);
            (0..n).map(|_| char::from(b"abcxyz_019-. "[self.below(13)])).collect()
        }
    }

    /// A name from `pool`, or (as junk) any string.
    pub fn name(&self, pool: &[&str]) -> String {
        if self.junky() || pool.is_empty() { self.junk_string() } else { self.pick(pool).to_string() }
    }

    /// A junk value of any type, nested up to `depth`.
    pub fn junk_value(&self, depth: usize) -> Doc {
        match self.below(if depth == 0 { 5 } else { 7 }) {
            0 => Doc::Num(self.wild()),
            1 => Doc::Str(self.junk_string()),
            2 => Doc::Bool(self.p(0.5)),
            3 => Doc::Int(self.pick(&[0, -1, i64::MAX, i64::MIN, 1 << 40, 7])),
            4 => Doc::Null,
            5 => {
                let n = self.int(0, 4);
                Doc::Seq((0..n).map(|_| self.junk_value(depth - 1)).collect())
            }
            _ => {
                let n = self.int(0, 3);
                Doc::Map((0..n).map(|_| (self.junk_string(), self.junk_value(depth - 1))).collect())
            }
        }
    }

    /// A number value in `[lo, hi)`, or junk.
    pub fn num(&self, lo: f64, hi: f64) -> Doc {
        if self.junky() { self.junk_value(1) } else { Doc::Num(self.f(lo, hi)) }
    }

    /// An integer value in `lo..hi`, or junk.
    pub fn integer(&self, lo: i64, hi: i64) -> Doc {
        if self.junky() {
            self.junk_value(1)
        } else {
            Doc::Int(lo + self.below(usize::try_from(hi - lo).unwrap_or(1).max(1)) as i64)
        }
    }

    /// `n` different names from `pool` (fewer if the pool is smaller), in random order; as
    /// junk, any names.
    pub fn distinct(&self, pool: &[&str], n: usize) -> Vec<String> {
        let mut all: Vec<&str> = pool.to_vec();
        for i in (1..all.len()).rev() {
            let j = self.below(i + 1);
            all.swap(i, j);
        }
        all.iter().take(n).map(|s| if self.junky() { self.junk_string() } else { s.to_string() }).collect()
    }

    /// A string value from `pool`, or junk.
    pub fn string(&self, pool: &[&str]) -> Doc {
        if self.junky() { self.junk_value(1) } else { Doc::Str(self.name(pool)) }
    }

    /// A boolean value, or junk.
    pub fn boolean(&self) -> Doc {
        if self.junky() { self.junk_value(1) } else { Doc::Bool(self.p(0.5)) }
    }

    /// The length of a list that should have `n` elements: `n`, or (as junk) another.
    pub fn len(&self, n: usize) -> usize {
        if self.junky() { self.pick(&[0, 1, n.saturating_sub(1), n + 1, 2 * n, 60]) } else { n }
    }

    /// `n` numbers in `[lo, hi)` (sometimes another count, sometimes junk).
    pub fn nums(&self, n: usize, lo: f64, hi: f64) -> Doc {
        if self.junky() {
            return self.junk_value(2);
        }
        let n = self.len(n);
        Doc::Seq((0..n).map(|_| self.num(lo, hi)).collect())
    }

    /// A list of `lo..hi` items made by `item`.
    pub fn seq(&self, lo: usize, hi: usize, mut item: impl FnMut(&G) -> Doc) -> Doc {
        if self.junky() {
            return self.junk_value(2);
        }
        let n = self.int(lo, hi);
        Doc::Seq((0..n).map(|_| item(self)).collect())
    }

    /// A mapping of the `entries` given, some dropped, some duplicated, junk keys added, perhaps
    /// shuffled.
    pub fn map(&self, entries: Vec<(&str, Doc)>) -> Doc {
        let mut out: Vec<(String, Doc)> = Vec::with_capacity(entries.len() + 1);
        for (k, v) in entries {
            if self.junky() {
                continue;
            }
            if self.p(self.junk / 20.0) {
                out.push((k.to_string(), v.clone()));
            }
            out.push((k.to_string(), v));
        }
        if self.junky() {
            let k = self.junk_string();
            let v = self.junk_value(2);
            out.push((k, v));
        }
        if self.junky() {
            for i in (1..out.len()).rev() {
                let j = self.below(i + 1);
                out.swap(i, j);
            }
        }
        Doc::Map(out)
    }

    /// A mapping where only some of the optional `entries` are present (each with probability
    /// `p`); `required` always are (unless junk drops them).
    pub fn some(&self, p: f64, required: Vec<(&str, Doc)>, optional: Vec<(&str, Doc)>) -> Doc {
        let mut all = required;
        for e in optional {
            if self.p(p) {
                all.push(e);
            }
        }
        self.map(all)
    }

    /// A document of random structure whose keys come from `keys` (and junk), up to `depth`.
    pub fn random_doc(&self, keys: &[&str], depth: usize) -> Doc {
        if depth == 0 || self.p(0.3) {
            return match self.below(4) {
                0 => Doc::Num(self.f(-10.0, 10.0)),
                1 => Doc::Str(self.name(keys)),
                2 => Doc::Int(self.below(20) as i64),
                _ => self.junk_value(0),
            };
        }
        if self.p(0.4) {
            let n = self.int(0, 6);
            Doc::Seq((0..n).map(|_| self.random_doc(keys, depth - 1)).collect())
        } else {
            let n = self.int(0, 6);
            Doc::Map((0..n).map(|_| (self.name(keys), self.random_doc(keys, depth - 1))).collect())
        }
    }

    /// An attribute value: `n` numbers (sometimes another count or junk words) separated by spaces.
    pub fn attr_nums(&self, n: usize, lo: f64, hi: f64) -> String {
        if self.junky() {
            return self.junk_string();
        }
        let n = self.len(n);
        (0..n).map(|_| fmt_num(self.f(lo, hi))).collect::<Vec<_>>().join(" ")
    }

    /// A random element tree with tags from `tags` and attributes from `attrs`.
    pub fn random_elem(&self, tags: &[&str], attrs: &[&str], depth: usize) -> Elem {
        let mut e = Elem { tag: self.name(tags), ..Elem::default() };
        if e.tag.is_empty() || !e.tag.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            e.tag = "x".into();
        }
        for _ in 0..self.int(0, 4) {
            let k = self.pick(attrs).to_string();
            let v = if self.p(0.5) { self.attr_nums(self.int(1, 4), -5.0, 5.0) } else { self.name(tags) };
            e.attrs.push((k, v));
        }
        if depth > 0 {
            for _ in 0..self.int(0, 5) {
                e.children.push(self.random_elem(tags, attrs, depth - 1));
            }
        }
        if self.p(0.1) {
            e.text = Some(self.junk_string());
        }
        e
    }
}

/// A number as text: plain for finite values, else one of the spellings each format has.
pub fn fmt_num(v: f64) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{v:?}")
    }
}

fn quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn bare_key(k: &str) -> bool {
    !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// JSON text of `doc`; non-finite numbers are written as JSON cannot hold them (`NaN`,
/// `1e999`) or as `null`.
pub fn to_json(doc: &Doc, g: &G) -> String {
    let mut s = String::new();
    json_into(doc, g, &mut s);
    s
}

fn json_into(doc: &Doc, g: &G, s: &mut String) {
    match doc {
        Doc::Map(entries) => {
            s.push('{');
            for (i, (k, v)) in entries.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                s.push_str(&quote(k));
                s.push(':');
                json_into(v, g, s);
            }
            s.push('}');
        }
        Doc::Seq(items) => {
            s.push('[');
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                json_into(v, g, s);
            }
            s.push(']');
        }
        Doc::Num(v) if v.is_finite() => s.push_str(&format!("{v:?}")),
        Doc::Num(v) => s.push_str(g.pick(&[if v.is_nan() { "NaN" } else { "1e999" }, "null", "-1e400"])),
        Doc::Int(i) => s.push_str(&i.to_string()),
        Doc::Str(t) => s.push_str(&quote(t)),
        Doc::Bool(b) => s.push_str(if *b { "true" } else { "false" }),
        Doc::Null => s.push_str("null"),
    }
}

/// YAML text of `doc`: block style, sequences of scalars sometimes in flow style, sometimes an
/// anchor and aliases to it.
pub fn to_yaml(doc: &Doc, g: &G) -> String {
    let mut s = String::new();
    let mut anchors = 0;
    yaml_into(doc, g, 0, &mut s, &mut anchors);
    if !s.ends_with('\n') {
        s.push('\n');
    }
    s
}

fn yaml_scalar(doc: &Doc) -> Option<String> {
    Some(match doc {
        Doc::Num(v) if v.is_nan() => ".nan".into(),
        Doc::Num(v) if v.is_infinite() => (if *v > 0.0 { ".inf" } else { "-.inf" }).into(),
        Doc::Num(v) => format!("{v:?}"),
        Doc::Int(i) => i.to_string(),
        Doc::Str(t) if bare_key(t) && t.parse::<f64>().is_err() && !matches!(t.as_str(), "true" | "false" | "null") => {
            t.clone()
        }
        Doc::Str(t) => quote(t),
        Doc::Bool(b) => b.to_string(),
        Doc::Null => "null".into(),
        Doc::Map(m) if m.is_empty() => "{}".into(),
        Doc::Seq(v) if v.is_empty() => "[]".into(),
        _ => return None,
    })
}

fn yaml_into(doc: &Doc, g: &G, indent: usize, s: &mut String, anchors: &mut usize) {
    let pad = " ".repeat(indent);
    match doc {
        Doc::Map(entries) if !entries.is_empty() => {
            for (k, v) in entries {
                s.push_str(&pad);
                s.push_str(&if bare_key(k) { k.clone() } else { quote(k) });
                s.push(':');
                value_after_key(v, g, indent, s, anchors);
            }
        }
        Doc::Seq(items) if !items.is_empty() => {
            for v in items {
                s.push_str(&pad);
                s.push('-');
                value_after_key(v, g, indent, s, anchors);
            }
        }
        other => {
            s.push_str(&pad);
            s.push_str(&yaml_scalar(other).unwrap_or_default());
            s.push('\n');
        }
    }
}

fn value_after_key(v: &Doc, g: &G, indent: usize, s: &mut String, anchors: &mut usize) {
    if *anchors > 0 && g.junky() {
        s.push_str(&format!(" *a{}\n", g.below(*anchors)));
        return;
    }
    if let Some(text) = yaml_scalar(v) {
        s.push(' ');
        s.push_str(&text);
        s.push('\n');
        return;
    }
    if g.junky() {
        s.push_str(&format!(" &a{anchors}"));
        *anchors += 1;
    }
    if let Doc::Seq(items) = v
        && items.iter().all(|i| !matches!(i, Doc::Map(_) | Doc::Seq(_)))
        && g.p(0.7)
    {
        let parts: Vec<String> = items.iter().map(|i| yaml_scalar(i).unwrap_or_default()).collect();
        s.push_str(&format!(" [{}]\n", parts.join(", ")));
        return;
    }
    s.push('\n');
    yaml_into(v, g, indent + 2, s, anchors);
}

/// TOML text of `doc` (a mapping): arrays of tables as `[[key]]` sections or inline, tables as
/// `[key]` sections or inline.
pub fn to_toml(doc: &Doc, g: &G) -> String {
    let Doc::Map(entries) = doc else { return format!("x = {}\n", toml_inline(doc)) };
    let mut head = String::new();
    let mut tail = String::new();
    for (k, v) in entries {
        let key = if bare_key(k) { k.clone() } else { quote(k) };
        match v {
            Doc::Seq(items) if !items.is_empty() && items.iter().all(|i| matches!(i, Doc::Map(_))) && g.p(0.8) => {
                for item in items {
                    tail.push_str(&format!("\n[[{key}]]\n"));
                    toml_table_body(item, &mut tail);
                }
            }
            Doc::Map(_) if g.p(0.8) => {
                tail.push_str(&format!("\n[{key}]\n"));
                toml_table_body(v, &mut tail);
            }
            _ => head.push_str(&format!("{key} = {}\n", toml_inline(v))),
        }
    }
    head + &tail
}

fn toml_table_body(doc: &Doc, s: &mut String) {
    if let Doc::Map(entries) = doc {
        for (k, v) in entries {
            let key = if bare_key(k) { k.clone() } else { quote(k) };
            s.push_str(&format!("{key} = {}\n", toml_inline(v)));
        }
    }
}

fn toml_inline(doc: &Doc) -> String {
    match doc {
        Doc::Map(entries) => {
            let parts: Vec<String> = entries
                .iter()
                .map(|(k, v)| format!("{} = {}", if bare_key(k) { k.clone() } else { quote(k) }, toml_inline(v)))
                .collect();
            format!("{{ {} }}", parts.join(", "))
        }
        Doc::Seq(items) => format!("[{}]", items.iter().map(toml_inline).collect::<Vec<_>>().join(", ")),
        Doc::Num(v) => fmt_num(*v),
        Doc::Int(i) => i.to_string(),
        Doc::Str(t) => quote(t),
        Doc::Bool(b) => b.to_string(),
        Doc::Null => "\"\"".into(),
    }
}

fn xml_escape(s: &str, junk: bool) -> String {
    if junk {
        return s.to_string();
    }
    s.replace('&', "&amp;").replace('<', "&lt;").replace('"', "&quot;")
}

/// XML text of `root`, sometimes with a declaration, comments or unescaped values.
pub fn to_xml(root: &Elem, g: &G) -> String {
    let mut s = String::new();
    if g.p(0.5) {
        s.push_str("<?xml version=\"1.0\"?>\n");
    }
    xml_into(root, g, 0, &mut s);
    s
}

fn xml_into(e: &Elem, g: &G, indent: usize, s: &mut String) {
    let pad = " ".repeat(indent);
    s.push_str(&pad);
    s.push('<');
    s.push_str(&e.tag);
    for (k, v) in &e.attrs {
        let junk = g.junky();
        s.push_str(&format!(" {k}=\"{}\"", xml_escape(v, junk)));
    }
    if e.children.is_empty() && e.text.is_none() {
        s.push_str("/>\n");
        return;
    }
    s.push_str(">\n");
    if let Some(t) = &e.text {
        let junk = g.junky();
        s.push_str(&xml_escape(t, junk));
    }
    if g.junky() {
        s.push_str("<!-- a comment -->");
    }
    for c in &e.children {
        xml_into(c, g, indent + 2, s);
    }
    s.push_str(&pad);
    s.push_str(&format!("</{}>\n", e.tag));
}

/// Tokens inserted by byte edits.
const TOKENS: [&str; 28] = [
    "", "0", "-1", "1e309", "nan", ".nan", "inf", "[", "]", "{", "}", "<", ">", "/>", "</", "=", ",", ":", "- ", "\n",
    "  ", "#", "\"", "'", "&", "*a0", "\u{0}", "é",
];

/// Random byte-level edits of `text`: deletions, token insertions, repeats; sometimes a cut.
pub fn mutate(bytes: &mut Vec<u8>, g: &G, edits: usize) {
    for _ in 0..edits {
        let len = bytes.len();
        let at = g.below(len + 1);
        match g.below(5) {
            0 => {
                let end = (at + g.int(1, 40)).min(len);
                bytes.drain(at..end);
            }
            1 => {
                let t = g.pick(&TOKENS);
                bytes.splice(at..at, t.bytes());
            }
            2 => {
                let end = (at + g.int(1, 80)).min(len);
                let copy = bytes[at..end].to_vec();
                bytes.splice(end..end, copy);
            }
            3 => {
                if at < len {
                    bytes[at] = g.next_u64() as u8;
                }
            }
            _ => {
                let end = (at + g.int(1, 12)).min(len);
                let t = g.pick(&TOKENS);
                bytes.splice(at..end, t.bytes());
            }
        }
    }
    if g.p(0.1) {
        let at = g.below(bytes.len() + 1);
        bytes.truncate(at);
    }
}

/// Finish a generated text: usually as is, sometimes cut short or edited.
pub fn finish(text: String, g: &G) -> Vec<u8> {
    let mut bytes = text.into_bytes();
    if g.p(0.15) {
        let edits = g.int(1, 4);
        mutate(&mut bytes, g, edits);
    } else if g.p(0.05) {
        let at = g.below(bytes.len() + 1);
        bytes.truncate(at);
    }
    bytes
}
