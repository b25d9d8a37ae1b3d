//! Reading one plugin's parameters and children by name and type, and refusing those the mapping did not read:
//! a parameter photonfarm has no counterpart for is an error at its line, never silently dropped.

use crate::scene::mitsuba::{Child, MitsubaError, Param, Plugin, Spectrum, SpectrumUse, Value};
use glam::{DMat4, DVec3};
use std::cell::RefCell;
use std::collections::HashSet;

/// A plugin being mapped: its parameters and named children, with the names read so far.
pub(super) struct Params<'p> {
    pub plugin: &'p Plugin,
    used: RefCell<HashSet<String>>,
    /// Children read so far, by index.
    used_children: RefCell<HashSet<usize>>,
}

impl<'p> Params<'p> {
    pub fn new(plugin: &'p Plugin) -> Self {
        Params { plugin, used: RefCell::new(HashSet::new()), used_children: RefCell::new(HashSet::new()) }
    }

    /// An error at the plugin's element.
    pub fn error(&self, message: impl Into<String>) -> MitsubaError {
        self.plugin.error(message)
    }

    /// An error at a parameter.
    pub fn error_at(&self, param: &Param, message: impl Into<String>) -> MitsubaError {
        MitsubaError::at(&param.position, format!("{} {}", self.plugin.element(), param.name), message)
    }

    /// The parameter `name`, marked as read.
    pub fn get(&self, name: &str) -> Option<&'p Param> {
        let p = self.plugin.param(name)?;
        self.used.borrow_mut().insert(name.to_string());
        Some(p)
    }

    /// Marks parameters as read without using them: those documented as ignored.
    pub fn ignore(&self, names: &[&str]) {
        for name in names {
            self.used.borrow_mut().insert(name.to_string());
        }
    }

    fn wrong(&self, p: &Param, wanted: &str) -> MitsubaError {
        self.error_at(p, format!("must be {wanted}, not a <{}>", p.value.tag()))
    }

    /// A number (`<float>` or `<integer>`).
    pub fn float(&self, name: &str) -> Result<Option<f64>, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(None) };
        match &p.value {
            Value::Float(x) => Ok(Some(*x)),
            Value::Integer(i) => Ok(Some(*i as f64)),
            _ => Err(self.wrong(p, "a <float>")),
        }
    }

    /// A number, `default` when absent.
    pub fn float_or(&self, name: &str, default: f64) -> Result<f64, MitsubaError> {
        Ok(self.float(name)?.unwrap_or(default))
    }

    pub fn integer(&self, name: &str) -> Result<Option<i64>, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(None) };
        match &p.value {
            Value::Integer(i) => Ok(Some(*i)),
            _ => Err(self.wrong(p, "an <integer>")),
        }
    }

    pub fn boolean(&self, name: &str, default: bool) -> Result<bool, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(default) };
        match &p.value {
            Value::Boolean(b) => Ok(*b),
            _ => Err(self.wrong(p, "a <boolean>")),
        }
    }

    pub fn string(&self, name: &str) -> Result<Option<&'p str>, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(None) };
        match &p.value {
            Value::String(s) => Ok(Some(s.as_str())),
            _ => Err(self.wrong(p, "a <string>")),
        }
    }

    pub fn point(&self, name: &str) -> Result<Option<DVec3>, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(None) };
        match &p.value {
            Value::Point(v) | Value::Vector(v) => Ok(Some(*v)),
            _ => Err(self.wrong(p, "a <point>")),
        }
    }

    /// A `<transform>`, the identity when absent.
    pub fn transform(&self, name: &str) -> Result<DMat4, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(DMat4::IDENTITY) };
        match &p.value {
            Value::Transform(m) => Ok(*m),
            _ => Err(self.wrong(p, "a <transform>")),
        }
    }

    /// A constant colour: `<rgb>`, `<spectrum>` (turned into RGB as Mitsuba does for `usage`) or a `<float>`
    /// grey.
    pub fn colour(&self, name: &str, usage: SpectrumUse) -> Result<Option<[f64; 3]>, MitsubaError> {
        let Some(p) = self.get(name) else { return Ok(None) };
        constant_colour(&p.value, usage).map(Some).ok_or_else(|| self.wrong(p, "an <rgb>, <spectrum> or <float>"))
    }

    /// The child plugin called `name` (written in place or by `<ref name=...>`), marked as read.
    pub fn child(&self, name: &str) -> Option<&'p Child> {
        let (i, c) = self.plugin.children.iter().enumerate().find(|(_, c)| c.name.as_deref() == Some(name))?;
        self.used_children.borrow_mut().insert(i);
        Some(c)
    }

    /// The children of `category` whatever their names, marked as read.
    pub fn children_of(&self, category: crate::scene::mitsuba::Category) -> Vec<&'p Child> {
        let mut out = Vec::new();
        for (i, c) in self.plugin.children.iter().enumerate() {
            if c.plugin.category == category {
                self.used_children.borrow_mut().insert(i);
                out.push(c);
            }
        }
        out
    }

    /// Refuses every parameter and child the mapping did not read.
    pub fn finish(&self) -> Result<(), MitsubaError> {
        let used = self.used.borrow();
        if let Some(p) = self.plugin.params.iter().find(|p| !used.contains(&p.name)) {
            return Err(
                self.error_at(p, format!("the parameter `{}` of {} is not supported", p.name, self.plugin.element()))
            );
        }
        let used = self.used_children.borrow();
        if let Some((_, c)) = self.plugin.children.iter().enumerate().find(|(i, _)| !used.contains(i)) {
            let what = c.name.as_deref().map(|n| format!(" (as `{n}`)")).unwrap_or_default();
            return Err(MitsubaError::at(
                &c.position,
                c.plugin.element(),
                format!("{}{what} inside {} is not supported", c.plugin.element(), self.plugin.element()),
            ));
        }
        Ok(())
    }
}

/// A value as a constant colour, when it is one.
pub(super) fn constant_colour(value: &Value, usage: SpectrumUse) -> Option<[f64; 3]> {
    match value {
        Value::Rgb(c) => Some(*c),
        Value::Float(x) => Some([*x; 3]),
        Value::Integer(i) => Some([*i as f64; 3]),
        Value::Spectrum(s) => Some(s.to_rgb(usage)),
        _ => None,
    }
}

/// A uniform spectrum's value, for parameters that take one number written as a spectrum.
pub(super) fn uniform(value: &Value) -> Option<f64> {
    match value {
        Value::Float(x) => Some(*x),
        Value::Integer(i) => Some(*i as f64),
        Value::Spectrum(Spectrum::Uniform(x)) => Some(*x),
        _ => None,
    }
}
