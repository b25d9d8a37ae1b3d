//! Selection expressions: logical combinations (`and`, `or`, `not`, parentheses) of the seed paper's elementary
//! optical events, parsed against a map's object and emitter names and tested on recorded paths.
//!
//! ```text
//! expr   := term ("or" term)*
//! term   := factor ("and" factor)*
//! factor := "not" factor | "(" expr ")" | atom
//! atom   := "light" "(" NAME ")"                  emitted by emitter NAME
//!         | "hits" "(" NAME ")"                   has a vertex on object NAME
//!         | EVENT "(" NAME | "*" ")" [CMP N]      EVENT at NAME (any object: *) N times (default >= 1)
//!         | "pixel" "(" X0 "," Y0 "," X1 "," Y1 ")" a camera path whose pixel lies in the rectangle
//!         | "ellipse" "(" CX "," CY "," RX "," RY ")"  … in the ellipse
//!         | "camera" | "lightpath" | "escaped"
//!         | "sensor"                              a light path that registered on the sensor
//! EVENT  := reflect | refract | diffuse | absorb | tir | emission
//! CMP    := ">=" | "<=" | "=" | ">" | "<"
//! ```
//! Names are bare (letters, digits, `_ - . [ ]`) or in double quotes.

use super::events::Events;
use super::format::{MapHeader, PathView};
use super::path::{PathKind, RecordedPath};

/// A parse error: what is wrong and the byte range of the offending token in the expression.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}\n  {expr}\n  {caret}", caret = caret(*start, *end))]
pub struct SelectError {
    pub message: String,
    pub expr: String,
    pub start: usize,
    pub end: usize,
}

fn caret(start: usize, end: usize) -> String {
    format!("{}{}", " ".repeat(start), "^".repeat((end - start).max(1)))
}

/// A comparison of an event count with a number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cmp {
    AtLeast,
    AtMost,
    Exactly,
    More,
    Less,
}

impl Cmp {
    fn holds(self, count: u32, n: u32) -> bool {
        match self {
            Cmp::AtLeast => count >= n,
            Cmp::AtMost => count <= n,
            Cmp::Exactly => count == n,
            Cmp::More => count > n,
            Cmp::Less => count < n,
        }
    }
}

/// A region of the image, in pixels (x to the right, y down, pixel (x, y) covering [x, x+1) × [y, y+1)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Region {
    /// Pixels whose centre lies in [x0, x1) × [y0, y1).
    Rect { x0: f32, y0: f32, x1: f32, y1: f32 },
    /// Pixels whose centre lies in the ellipse.
    Ellipse { cx: f32, cy: f32, rx: f32, ry: f32 },
}

impl Region {
    /// True when pixel (x, y)'s centre lies in the region.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        match *self {
            Region::Rect { x0, y0, x1, y1 } => px >= x0 && px < x1 && py >= y0 && py < y1,
            Region::Ellipse { cx, cy, rx, ry } => {
                let (dx, dy) = ((px - cx) / rx, (py - cy) / ry);
                dx * dx + dy * dy <= 1.0
            }
        }
    }
}

/// A compiled selection expression.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    And(Box<Expr>, Box<Expr>),
    Or(Box<Expr>, Box<Expr>),
    Not(Box<Expr>),
    /// A light path from one of these emitters, or a camera path with an emission event on one of these objects.
    Emitted {
        emitters: Vec<u32>,
        objects: Vec<u16>,
    },
    /// The number of vertices on one of `objects` (any object when None) carrying every bit of `events` (any
    /// vertex when empty) compares with `n`.
    Count {
        objects: Option<Vec<u16>>,
        events: Events,
        cmp: Cmp,
        n: u32,
    },
    /// A camera path whose pixel lies in the region (a light path never does).
    Pixel(Region),
    Kind(PathKind),
    Escaped,
}

/// What a selection tests of a path: its kind, its source and each vertex's object and events. A decoded
/// `RecordedPath` and a `PathView` over a portion's raw bytes both provide them, so one `Expr::matches` tests
/// either.
pub trait Selectable {
    fn kind(&self) -> PathKind;
    /// As `RecordedPath::source`.
    fn source(&self) -> u32;
    /// Each vertex's object and events, the origin first.
    fn objects_and_events(&self) -> impl Iterator<Item = (u16, Events)> + '_;
    /// The last vertex's events (none for a path without vertices).
    fn last_events(&self) -> Events;
}

impl Selectable for RecordedPath {
    fn kind(&self) -> PathKind {
        self.kind
    }
    fn source(&self) -> u32 {
        self.source
    }
    fn objects_and_events(&self) -> impl Iterator<Item = (u16, Events)> + '_ {
        self.vertices.iter().map(|v| (v.object, v.events))
    }
    fn last_events(&self) -> Events {
        self.vertices.last().map_or(Events::default(), |v| v.events)
    }
}

impl Selectable for PathView<'_> {
    #[inline]
    fn kind(&self) -> PathKind {
        self.kind
    }
    #[inline]
    fn source(&self) -> u32 {
        self.source
    }
    #[inline]
    fn objects_and_events(&self) -> impl Iterator<Item = (u16, Events)> + '_ {
        PathView::objects_and_events(self)
    }
    #[inline]
    fn last_events(&self) -> Events {
        PathView::last_events(self)
    }
}

impl Expr {
    /// True when `path` satisfies the expression; `width` is the image's, to find a pixel's column and row.
    pub fn matches<P: Selectable>(&self, path: &P, width: u32) -> bool {
        match self {
            Expr::And(a, b) => a.matches(path, width) && b.matches(path, width),
            Expr::Or(a, b) => a.matches(path, width) || b.matches(path, width),
            Expr::Not(a) => !a.matches(path, width),
            Expr::Emitted { emitters, objects } => match path.kind() {
                PathKind::Light => emitters.contains(&path.source()),
                PathKind::Camera => path
                    .objects_and_events()
                    .any(|(object, events)| events.contains(Events::EMISSION) && objects.contains(&object)),
            },
            Expr::Count { objects, events, cmp, n } => {
                let count = path
                    .objects_and_events()
                    .filter(|(object, _)| objects.as_ref().is_none_or(|o| o.contains(object)))
                    .filter(|(_, e)| events.0 == 0 || e.contains(*events))
                    .count();
                cmp.holds(count.min(u32::MAX as usize) as u32, *n)
            }
            Expr::Pixel(region) => {
                path.kind() == PathKind::Camera
                    && width > 0
                    && region.contains(path.source() % width, path.source() / width)
            }
            Expr::Kind(k) => path.kind() == *k,
            Expr::Escaped => path.last_events().contains(Events::ESCAPED),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Word(String),
    Quoted(String),
    Number(f64),
    Open,
    Close,
    Comma,
    Star,
    Cmp(Cmp),
}

struct Token {
    tok: Tok,
    start: usize,
    end: usize,
}

fn is_name_char(c: char) -> bool {
    c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | '[' | ']')
}

fn tokenize(expr: &str) -> Result<Vec<Token>, SelectError> {
    let err = |message: String, start: usize, end: usize| SelectError { message, expr: expr.to_string(), start, end };
    let mut out = Vec::new();
    let chars: Vec<(usize, char)> = expr.char_indices().collect();
    let mut i = 0;
    while i < chars.len() {
        let (at, c) = chars[i];
        let single = |tok| Token { tok, start: at, end: at + c.len_utf8() };
        match c {
            c if c.is_whitespace() => i += 1,
            '(' | ')' | ',' | '*' => {
                out.push(single(match c {
                    '(' => Tok::Open,
                    ')' => Tok::Close,
                    ',' => Tok::Comma,
                    _ => Tok::Star,
                }));
                i += 1;
            }
            '>' | '<' | '=' => {
                let next = chars.get(i + 1).map(|&(_, c)| c);
                let (cmp, len) = match (c, next) {
                    ('>', Some('=')) => (Cmp::AtLeast, 2),
                    ('<', Some('=')) => (Cmp::AtMost, 2),
                    ('=', Some('=')) => (Cmp::Exactly, 2),
                    ('>', _) => (Cmp::More, 1),
                    ('<', _) => (Cmp::Less, 1),
                    _ => (Cmp::Exactly, 1),
                };
                out.push(Token { tok: Tok::Cmp(cmp), start: at, end: at + len });
                i += len;
            }
            '"' => {
                let close = chars[i + 1..].iter().position(|&(_, c)| c == '"');
                let Some(close) = close else {
                    return Err(err("this quote is never closed".into(), at, expr.len()));
                };
                let end = chars[i + 1 + close].0;
                out.push(Token { tok: Tok::Quoted(expr[at + 1..end].to_string()), start: at, end: end + 1 });
                i += close + 2;
            }
            c if is_name_char(c) => {
                let mut j = i;
                while j < chars.len() && is_name_char(chars[j].1) {
                    j += 1;
                }
                let end = chars.get(j).map_or(expr.len(), |&(a, _)| a);
                let text = &expr[at..end];
                let tok = match text.parse::<f64>() {
                    Ok(n) if text.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '.') => Tok::Number(n),
                    _ => Tok::Word(text.to_string()),
                };
                out.push(Token { tok, start: at, end });
                i = j;
            }
            _ => return Err(err(format!("'{c}' has no meaning in a selection"), at, at + c.len_utf8())),
        }
    }
    Ok(out)
}

/// Parses `expr` against the names of `header`'s scene.
pub fn parse(expr: &str, header: &MapHeader) -> Result<Expr, SelectError> {
    let tokens = tokenize(expr)?;
    let mut p = Parser { expr, header, tokens, at: 0 };
    if p.tokens.is_empty() {
        return Err(p.error_at("the selection is empty".into(), 0, expr.len()));
    }
    let e = p.or()?;
    if let Some(t) = p.tokens.get(p.at) {
        return Err(p.error_at("expected `and`, `or` or the end of the selection here".into(), t.start, t.end));
    }
    Ok(e)
}

struct Parser<'a> {
    expr: &'a str,
    header: &'a MapHeader,
    tokens: Vec<Token>,
    at: usize,
}

const EXPECTED_ATOM: &str = "expected an event (light, hits, reflect, refract, diffuse, absorb, tir, emission, \
                             pixel, ellipse, camera, lightpath, escaped, sensor), `not` or `(`";

const EVENT_WORDS: [(&str, Events); 6] = [
    ("reflect", Events::REFLECT),
    ("refract", Events::REFRACT),
    ("diffuse", Events::DIFFUSE),
    ("absorb", Events::ABSORB),
    ("tir", Events::TIR),
    ("emission", Events::EMISSION),
];

impl Parser<'_> {
    fn error_at(&self, message: String, start: usize, end: usize) -> SelectError {
        SelectError { message, expr: self.expr.to_string(), start, end }
    }

    /// An error at the current token (or the end).
    fn error(&self, message: &str) -> SelectError {
        match self.tokens.get(self.at) {
            Some(t) => self.error_at(message.to_string(), t.start, t.end),
            None => self.error_at(format!("{message}, but the selection ends"), self.expr.len(), self.expr.len()),
        }
    }

    fn peek_word(&self, word: &str) -> bool {
        matches!(self.tokens.get(self.at), Some(Token { tok: Tok::Word(w), .. }) if w.eq_ignore_ascii_case(word))
    }

    fn expect(&mut self, tok: Tok, what: &str) -> Result<(), SelectError> {
        match self.tokens.get(self.at) {
            Some(t) if t.tok == tok => {
                self.at += 1;
                Ok(())
            }
            _ => Err(self.error(&format!("expected {what}"))),
        }
    }

    fn or(&mut self) -> Result<Expr, SelectError> {
        let mut e = self.and()?;
        while self.peek_word("or") {
            self.at += 1;
            e = Expr::Or(Box::new(e), Box::new(self.and()?));
        }
        Ok(e)
    }

    fn and(&mut self) -> Result<Expr, SelectError> {
        let mut e = self.factor()?;
        while self.peek_word("and") {
            self.at += 1;
            e = Expr::And(Box::new(e), Box::new(self.factor()?));
        }
        Ok(e)
    }

    fn factor(&mut self) -> Result<Expr, SelectError> {
        if self.peek_word("not") {
            self.at += 1;
            return Ok(Expr::Not(Box::new(self.factor()?)));
        }
        if matches!(self.tokens.get(self.at), Some(Token { tok: Tok::Open, .. })) {
            self.at += 1;
            let e = self.or()?;
            self.expect(Tok::Close, "`)`")?;
            return Ok(e);
        }
        self.atom()
    }

    fn atom(&mut self) -> Result<Expr, SelectError> {
        let Some(Token { tok: Tok::Word(word), start, end }) = self.tokens.get(self.at) else {
            return Err(self.error(EXPECTED_ATOM));
        };
        let (word, start, end) = (word.to_ascii_lowercase(), *start, *end);
        self.at += 1;
        match word.as_str() {
            "camera" => Ok(Expr::Kind(PathKind::Camera)),
            "lightpath" => Ok(Expr::Kind(PathKind::Light)),
            "escaped" => Ok(Expr::Escaped),
            // A light path's sensor vertices are where it registered; a camera path's origin is its only one.
            "sensor" => Ok(Expr::And(
                Box::new(Expr::Kind(PathKind::Light)),
                Box::new(Expr::Count { objects: None, events: Events::SENSOR, cmp: Cmp::AtLeast, n: 1 }),
            )),
            "light" => {
                self.expect(Tok::Open, "`(` and an emitter's name")?;
                let (name, s, e) = self.name()?;
                let emitters = ids(&self.header.emitters, &name);
                if emitters.is_empty() {
                    let known = self.header.emitters.join(", ");
                    return Err(self.error_at(format!("no emitter is called '{name}' (emitters: {known})"), s, e));
                }
                let objects = emitters.iter().filter_map(|&i| u16::try_from(i).ok()).collect();
                self.expect(Tok::Close, "`)`")?;
                Ok(Expr::Emitted { emitters, objects })
            }
            "hits" => {
                self.expect(Tok::Open, "`(` and an object's name")?;
                let objects = Some(self.objects()?);
                self.expect(Tok::Close, "`)`")?;
                Ok(Expr::Count { objects, events: Events::default(), cmp: Cmp::AtLeast, n: 1 })
            }
            "pixel" | "ellipse" => {
                self.expect(Tok::Open, "`(` and four numbers")?;
                let mut v = [0f32; 4];
                for (i, x) in v.iter_mut().enumerate() {
                    if i > 0 {
                        self.expect(Tok::Comma, "`,`")?;
                    }
                    *x = self.number()? as f32;
                }
                self.expect(Tok::Close, "`)`")?;
                let [a, b, c, d] = v;
                if word == "ellipse" && !(c > 0.0 && d > 0.0) {
                    return Err(self.error_at("an ellipse's radii must be positive".into(), start, end));
                }
                Ok(Expr::Pixel(if word == "pixel" {
                    Region::Rect { x0: a, y0: b, x1: c, y1: d }
                } else {
                    Region::Ellipse { cx: a, cy: b, rx: c, ry: d }
                }))
            }
            w => {
                let Some(&(_, events)) = EVENT_WORDS.iter().find(|(n, _)| *n == w) else {
                    return Err(self.error_at(format!("{EXPECTED_ATOM}, not '{w}'"), start, end));
                };
                self.expect(Tok::Open, "`(` and an object's name or *")?;
                let objects = if matches!(self.tokens.get(self.at), Some(Token { tok: Tok::Star, .. })) {
                    self.at += 1;
                    None
                } else {
                    Some(self.objects()?)
                };
                self.expect(Tok::Close, "`)`")?;
                let (cmp, n) = match self.tokens.get(self.at) {
                    Some(Token { tok: Tok::Cmp(c), .. }) => {
                        let c = *c;
                        self.at += 1;
                        let at = self.tokens.get(self.at).map(|t| (t.start, t.end));
                        let n = self.number()?;
                        if !(n >= 0.0 && n.fract() == 0.0 && n <= u32::MAX as f64) {
                            let (s, e) = at.unwrap_or((0, 0));
                            return Err(self.error_at("a count must be a whole number ≥ 0".into(), s, e));
                        }
                        (c, n as u32)
                    }
                    _ => (Cmp::AtLeast, 1),
                };
                Ok(Expr::Count { objects, events, cmp, n })
            }
        }
    }

    fn name(&mut self) -> Result<(String, usize, usize), SelectError> {
        match self.tokens.get(self.at) {
            Some(Token { tok: Tok::Word(w) | Tok::Quoted(w), start, end }) => {
                self.at += 1;
                Ok((w.clone(), *start, *end))
            }
            Some(Token { tok: Tok::Number(_), start, end }) => {
                self.at += 1;
                Ok((self.expr[*start..*end].to_string(), *start, *end))
            }
            _ => Err(self.error("expected a name")),
        }
    }

    fn objects(&mut self) -> Result<Vec<u16>, SelectError> {
        let (name, s, e) = self.name()?;
        let found: Vec<u16> =
            ids(&self.header.objects, &name).into_iter().filter_map(|i| u16::try_from(i).ok()).collect();
        if found.is_empty() {
            let known = self.header.objects.join(", ");
            return Err(self.error_at(format!("no object is called '{name}' (objects: {known})"), s, e));
        }
        Ok(found)
    }

    fn number(&mut self) -> Result<f64, SelectError> {
        match self.tokens.get(self.at) {
            Some(Token { tok: Tok::Number(n), .. }) => {
                let n = *n;
                self.at += 1;
                Ok(n)
            }
            _ => Err(self.error("expected a number")),
        }
    }
}

/// The indices of every entry of `names` equal to `name`.
fn ids(names: &[String], name: &str) -> Vec<u32> {
    names.iter().enumerate().filter(|(_, n)| *n == name).map(|(i, _)| i as u32).collect()
}
