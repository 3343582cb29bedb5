//! A small checked reader over a TOML table: every getter knows the file and the key path, so
//! every error says where and what is allowed; `finish` rejects keys nobody asked for.

use std::cell::RefCell;
use std::ops::RangeInclusive;
use std::path::Path;

use toml::{Table, Value};

use super::catalog::{self, num, FileKind, Spec};
use super::ConfigError;

pub(crate) struct Reader<'a> {
    pub file: &'a Path,
    pub path: String,
    /// Which kind of file it reads, for the key catalog ([`catalog`]).
    kind: FileKind,
    table: &'a Table,
    known: RefCell<Vec<&'static str>>,
}

pub(crate) fn parse_file(file: &Path) -> Result<Table, ConfigError> {
    let text = super::read_bounded_text(file, super::MAX_CONFIG_BYTES)
        .map_err(|e| ConfigError::new(file, "", format!("cannot read the file: {e}")))?;
    text.parse::<Table>().map_err(|e| {
        ConfigError::new(
            file,
            "",
            format!("not valid TOML: {}", e.to_string().trim_end()),
        )
    })
}

impl<'a> Reader<'a> {
    /// The reader of a whole file of `kind`.
    pub fn root(file: &'a Path, kind: FileKind, table: &'a Table) -> Self {
        Reader::new(file, kind, String::new(), table)
    }

    fn new(file: &'a Path, kind: FileKind, path: String, table: &'a Table) -> Self {
        Reader {
            file,
            path,
            kind,
            table,
            known: RefCell::new(Vec::new()),
        }
    }

    /// Tells the key catalog (when one is being made) what this getter checks of `key`.
    fn note(&self, key: &str, spec: impl FnOnce() -> Spec) {
        catalog::note(self.kind, || self.key(key), spec);
    }

    pub fn key(&self, key: &str) -> String {
        if self.path.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.path)
        }
    }

    pub fn err(&self, key: &str, problem: impl Into<String>) -> ConfigError {
        ConfigError::new(self.file, self.key(key), problem)
    }

    fn get(&self, key: &'static str) -> Option<&'a Value> {
        self.known.borrow_mut().push(key);
        self.table.get(key)
    }

    pub fn has(&self, key: &'static str) -> bool {
        self.known.borrow_mut().push(key);
        self.table.contains_key(key)
    }

    /// Rejects every key that no getter asked for.
    pub fn finish(self) -> Result<(), ConfigError> {
        let known = self.known.borrow();
        for key in self.table.keys() {
            if !known.iter().any(|k| k == key) {
                let mut allowed: Vec<&str> = known.clone();
                allowed.sort();
                allowed.dedup();
                // The nearest allowed key, when one is near enough to be what was meant.
                let meant = allowed
                    .iter()
                    .filter(|k| super::near_enough(key, k))
                    .min_by_key(|k| super::edit_distance(key, k))
                    .map_or(String::new(), |k| format!(" (did you mean `{k}`?)"));
                return Err(self.err(
                    key,
                    format!("unknown key{meant}; allowed here: {}", allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }

    pub fn table(&self, key: &'static str) -> Result<Option<Reader<'a>>, ConfigError> {
        self.note(key, || Spec::of("table"));
        match self.get(key) {
            None => Ok(None),
            Some(Value::Table(t)) => Ok(Some(Reader::new(self.file, self.kind, self.key(key), t))),
            Some(v) => Err(self.err(key, format!("expected a table, found {}", v.type_str()))),
        }
    }

    /// An array of tables (`[[key]]`).
    pub fn tables(&self, key: &'static str) -> Result<Vec<Reader<'a>>, ConfigError> {
        self.note(key, || Spec::of("array of tables"));
        match self.get(key) {
            None => Ok(Vec::new()),
            Some(Value::Array(items)) => items
                .iter()
                .enumerate()
                .map(|(i, v)| match v {
                    Value::Table(t) => Ok(Reader::new(
                        self.file,
                        self.kind,
                        format!("{}[{i}]", self.key(key)),
                        t,
                    )),
                    v => Err(self.err(
                        key,
                        format!("expected tables ([[{key}]]), found {}", v.type_str()),
                    )),
                })
                .collect(),
            Some(v) => Err(self.err(
                key,
                format!("expected [[{key}]] tables, found {}", v.type_str()),
            )),
        }
    }

    pub fn string(&self, key: &'static str) -> Result<Option<String>, ConfigError> {
        self.note(key, || Spec::of("string"));
        self.string_value(key)
    }

    /// A string, or `default` when absent.
    pub fn string_or(&self, key: &'static str, default: &str) -> Result<String, ConfigError> {
        self.note(key, || Spec {
            default: Some(format!("{default:?}")),
            ..Spec::of("string")
        });
        Ok(self
            .string_value(key)?
            .unwrap_or_else(|| default.to_string()))
    }

    fn string_value(&self, key: &'static str) -> Result<Option<String>, ConfigError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.clone())),
            Some(v) => Err(self.err(key, format!("expected a string, found {}", v.type_str()))),
        }
    }

    /// One of `allowed` (the first is the default when the key is absent).
    pub fn choice(
        &self,
        key: &'static str,
        allowed: &[&'static str],
    ) -> Result<&'static str, ConfigError> {
        self.note(key, || Spec {
            allowed: quoted(allowed),
            default: allowed.first().map(|a| format!("{a:?}")),
            ..Spec::of("string")
        });
        match self.string_value(key)? {
            None => Ok(allowed[0]),
            Some(s) => allowed.iter().copied().find(|a| *a == s).ok_or_else(|| {
                self.err(
                    key,
                    format!("{s:?} is not allowed; one of: {}", quoted(allowed)),
                )
            }),
        }
    }

    pub fn bool(&self, key: &'static str, default: bool) -> Result<bool, ConfigError> {
        self.note(key, || Spec {
            default: Some(default.to_string()),
            ..Spec::of("true or false")
        });
        match self.get(key) {
            None => Ok(default),
            Some(Value::Boolean(b)) => Ok(*b),
            Some(v) => Err(self.err(
                key,
                format!("expected true or false, found {}", v.type_str()),
            )),
        }
    }

    fn number(&self, key: &str, v: &Value) -> Result<f64, ConfigError> {
        match v {
            Value::Float(f) => Ok(*f),
            Value::Integer(i) => Ok(*i as f64),
            v => Err(self.err(key, format!("expected a number, found {}", v.type_str()))),
        }
    }

    /// A finite number in `range` (inclusive), or `default` when absent.
    pub fn f64_in(
        &self,
        key: &'static str,
        default: Option<f64>,
        range: RangeInclusive<f64>,
    ) -> Result<Option<f64>, ConfigError> {
        self.note(key, || Spec {
            allowed: span(&range),
            default: default.map(num),
            ..Spec::of("number")
        });
        self.f64_value(key, default, range)
    }

    fn f64_value(
        &self,
        key: &'static str,
        default: Option<f64>,
        range: RangeInclusive<f64>,
    ) -> Result<Option<f64>, ConfigError> {
        match self.get(key) {
            None => Ok(default),
            Some(v) => {
                let x = self.number(key, v)?;
                check_range(x, &range).map_err(|p| self.err(key, p))?;
                Ok(Some(x))
            }
        }
    }

    pub fn f64_required(
        &self,
        key: &'static str,
        range: RangeInclusive<f64>,
    ) -> Result<f64, ConfigError> {
        self.note(key, || Spec {
            allowed: span(&range),
            default: Some("required".into()),
            ..Spec::of("number")
        });
        self.f64_value(key, None, range)?
            .ok_or_else(|| self.err(key, "required; add it to the table"))
    }

    /// A whole number in `range`, or `default` when absent.
    pub fn u64_in(
        &self,
        key: &'static str,
        default: u64,
        range: RangeInclusive<u64>,
    ) -> Result<u64, ConfigError> {
        self.note(key, || Spec {
            allowed: format!("{} to {}", range.start(), range.end()),
            default: Some(default.to_string()),
            ..Spec::of("whole number")
        });
        self.u64_value(key, default, range)
    }

    fn u64_value(
        &self,
        key: &'static str,
        default: u64,
        range: RangeInclusive<u64>,
    ) -> Result<u64, ConfigError> {
        match self.get(key) {
            None => Ok(default),
            Some(Value::Integer(i)) if *i >= 0 && range.contains(&(*i as u64)) => Ok(*i as u64),
            Some(Value::Integer(i)) => Err(self.err(
                key,
                format!(
                    "{i} is out of range; allowed: {} to {}",
                    range.start(),
                    range.end()
                ),
            )),
            Some(v) => Err(self.err(
                key,
                format!("expected a whole number, found {}", v.type_str()),
            )),
        }
    }

    /// A whole number in `range`, or None when absent.
    pub fn u64_opt(
        &self,
        key: &'static str,
        range: RangeInclusive<u64>,
    ) -> Result<Option<u64>, ConfigError> {
        self.note(key, || Spec {
            allowed: format!("{} to {}", range.start(), range.end()),
            ..Spec::of("whole number")
        });
        if self.has(key) {
            self.u64_value(key, 0, range).map(Some)
        } else {
            Ok(None)
        }
    }

    /// A list of `N` finite numbers, each in `range`.
    pub fn array<const N: usize>(
        &self,
        key: &'static str,
        range: RangeInclusive<f64>,
    ) -> Result<Option<[f64; N]>, ConfigError> {
        self.note(key, || array_spec::<N>(&range, None));
        self.array_value(key, range)
    }

    /// [`Reader::array`], or `default` when absent.
    pub fn array_or<const N: usize>(
        &self,
        key: &'static str,
        range: RangeInclusive<f64>,
        default: [f64; N],
    ) -> Result<[f64; N], ConfigError> {
        self.note(key, || array_spec::<N>(&range, Some(&default)));
        Ok(self.array_value(key, range)?.unwrap_or(default))
    }

    fn array_value<const N: usize>(
        &self,
        key: &'static str,
        range: RangeInclusive<f64>,
    ) -> Result<Option<[f64; N]>, ConfigError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => vector::<N>(v, &range)
                .map(Some)
                .map_err(|p| self.err(key, p)),
        }
    }

    /// A list of numbers of any length, each in `range`.
    pub fn numbers(
        &self,
        key: &'static str,
        range: RangeInclusive<f64>,
    ) -> Result<Option<Vec<f64>>, ConfigError> {
        self.note(key, || Spec {
            allowed: format!("each {}", span(&range)),
            ..Spec::of("list of numbers")
        });
        match self.get(key) {
            None => Ok(None),
            Some(Value::Array(items)) => items
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    let x = self.number(key, v)?;
                    check_range(x, &range).map_err(|p| self.err(key, format!("item {i}: {p}")))?;
                    Ok(x)
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
            Some(v) => Err(self.err(
                key,
                format!("expected a list of numbers, found {}", v.type_str()),
            )),
        }
    }

    /// The raw value, for shapes the reader has no getter for; `spec` says, for the key
    /// catalog, what the caller accepts.
    pub fn raw(&self, key: &'static str, spec: impl FnOnce() -> Spec) -> Option<&'a Value> {
        self.note(key, spec);
        self.get(key)
    }
}

/// `lo to hi`, as the errors say it.
pub(crate) fn span(range: &RangeInclusive<f64>) -> String {
    format!("{} to {}", range.start(), range.end())
}

fn array_spec<const N: usize>(range: &RangeInclusive<f64>, default: Option<&[f64; N]>) -> Spec {
    Spec {
        ty: format!("list of {N} numbers"),
        allowed: format!("each {}", span(range)),
        default: default.map(|d| catalog::list(d)),
    }
}

pub(crate) fn check_range(x: f64, range: &RangeInclusive<f64>) -> Result<(), String> {
    if !x.is_finite() {
        return Err(format!("{x} is not a finite number"));
    }
    if !range.contains(&x) {
        return Err(format!(
            "{x} is out of range; allowed: {} to {}",
            range.start(),
            range.end()
        ));
    }
    Ok(())
}

/// `[x, y, z, ...]` with exactly N finite numbers in `range`.
pub(crate) fn vector<const N: usize>(
    v: &Value,
    range: &RangeInclusive<f64>,
) -> Result<[f64; N], String> {
    let Value::Array(items) = v else {
        return Err(format!(
            "expected a list of {N} numbers, found {}",
            v.type_str()
        ));
    };
    if items.len() != N {
        return Err(format!("expected {N} numbers, found {}", items.len()));
    }
    let mut out = [0.0; N];
    for (i, item) in items.iter().enumerate() {
        let x = match item {
            Value::Float(f) => *f,
            Value::Integer(n) => *n as f64,
            v => {
                return Err(format!(
                    "item {i}: expected a number, found {}",
                    v.type_str()
                ))
            }
        };
        check_range(x, range).map_err(|p| format!("item {i}: {p}"))?;
        out[i] = x;
    }
    Ok(out)
}

pub(crate) fn quoted(items: &[&str]) -> String {
    items
        .iter()
        .map(|s| format!("{s:?}"))
        .collect::<Vec<_>>()
        .join(", ")
}
