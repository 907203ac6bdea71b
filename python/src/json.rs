//! JSON between Python objects and text, with serde_json, so that
//! `import zwidth` and the engines never load Python's `json` (and the
//! regular expressions it compiles: most of the import's time,
//! docs/python.md "Speed"). `loads` keeps a document's key order, as
//! `json.loads` does; `dumps` refuses NaN, infinities and what JSON cannot
//! hold with a ValueError naming where the value is.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use pyo3::IntoPyObjectExt;
use serde::de::{self, DeserializeSeed, MapAccess, SeqAccess, Visitor};
use serde::ser::{self, Serialize, SerializeMap, SerializeSeq};

/// JSON text as Python objects (dicts in the document's key order).
#[pyfunction]
pub fn loads(py: Python<'_>, text: &str) -> PyResult<Py<PyAny>> {
    let mut de = serde_json::Deserializer::from_str(text);
    let value = Build(py)
        .deserialize(&mut de)
        .and_then(|v| de.end().map(|_| v))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(value)
}

/// A Python value (dicts with str keys, lists, tuples, str, int, float,
/// bool, None; numpy numbers by value) as JSON text. `name` is the
/// argument it came from, the start of the path an error names ("": the
/// dict's keys are the arguments).
#[pyfunction]
pub fn dumps(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<String> {
    serde_json::to_string(&Walk {
        obj,
        path: name.to_string(),
        depth: 0,
    })
    .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Builds the Python object of one JSON value.
struct Build<'py>(Python<'py>);

fn py_err<E: de::Error>(e: PyErr) -> E {
    E::custom(e)
}

impl<'de, 'py> DeserializeSeed<'de> for Build<'py> {
    type Value = Py<PyAny>;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de, 'py> Visitor<'de> for Build<'py> {
    type Value = Py<PyAny>;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a JSON value")
    }
    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        Ok(self.0.None())
    }
    fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
        v.into_py_any(self.0).map_err(py_err)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
        v.into_py_any(self.0).map_err(py_err)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
        v.into_py_any(self.0).map_err(py_err)
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
        v.into_py_any(self.0).map_err(py_err)
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
        v.into_py_any(self.0).map_err(py_err)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let list = PyList::empty(self.0);
        while let Some(v) = seq.next_element_seed(Build(self.0))? {
            list.append(v).map_err(py_err)?;
        }
        Ok(list.into_any().unbind())
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let dict = PyDict::new(self.0);
        while let Some(k) = map.next_key::<std::borrow::Cow<'de, str>>()? {
            let v = map.next_value_seed(Build(self.0))?;
            dict.set_item(k.as_ref(), v).map_err(py_err)?;
        }
        Ok(dict.into_any().unbind())
    }
}

/// A Python object being written, with its path from the argument
/// (`scene.device.mass`, `estimators[2]`) for the error.
struct Walk<'a, 'py> {
    obj: &'a Bound<'py, PyAny>,
    path: String,
    /// Dicts and lists it sits in.
    depth: usize,
}

/// Deepest nesting `dumps` writes: every spec is a few levels deep, and a
/// dict or list that contains itself would otherwise be walked until the
/// stack overflows (the interpreter crashed: issue 45).
pub const MAX_DEPTH: usize = 32;

impl<'py> Walk<'_, 'py> {
    /// The walk of `obj`, an entry of this one at `path`.
    fn inner<'b>(&self, obj: &'b Bound<'py, PyAny>, path: String) -> Walk<'b, 'py> {
        Walk {
            obj,
            path,
            depth: self.depth + 1,
        }
    }

    /// The path of a dict's entry (the argument's own keys unprefixed when
    /// it has no name: a spec built here names `scene.device.mass`).
    fn child(&self, key: &str) -> String {
        if self.path.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.path)
        }
    }

    fn refuse<E: ser::Error>(&self, why: &str) -> E {
        let shown = self
            .obj
            .repr()
            .map(|r| r.to_string())
            .unwrap_or_else(|_| "?".into());
        E::custom(format!("{} = {shown} is not allowed: {why}", self.path))
    }
}

impl Serialize for Walk<'_, '_> {
    fn serialize<S: ser::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let o = self.obj;
        if o.is_none() {
            return s.serialize_unit();
        }
        if self.depth > MAX_DEPTH {
            // Not its repr: that would walk the same nesting.
            return Err(ser::Error::custom(format!(
                "{} is nested more than {MAX_DEPTH} dicts or lists deep: a spec is a few levels deep (does a dict or list contain itself?)",
                self.path
            )));
        }
        if let Ok(b) = o.cast::<PyBool>() {
            return s.serialize_bool(b.is_true());
        }
        if let Ok(d) = o.cast::<PyDict>() {
            // A snapshot of the items: a value whose `__float__` or
            // `__index__` changes the dict would make pyo3's iterator panic
            // (a PanicException past `except Exception`: issue 45).
            let items: Vec<(Bound<'_, PyAny>, Bound<'_, PyAny>)> = d
                .items()
                .iter()
                .map(|kv| kv.extract())
                .collect::<PyResult<_>>()
                .map_err(ser::Error::custom)?;
            let mut m = s.serialize_map(Some(items.len()))?;
            for (k, v) in items {
                let Ok(key) = k.cast::<PyString>() else {
                    return Err(self
                        .inner(&k, format!("{} key", self.path).trim_start().to_string())
                        .refuse("keys must be str"));
                };
                let key = key.to_cow().map_err(ser::Error::custom)?;
                m.serialize_entry(key.as_ref(), &self.inner(&v, self.child(&key)))?;
            }
            return m.end();
        }
        if o.is_instance_of::<PyList>() || o.is_instance_of::<PyTuple>() {
            let items: Vec<Bound<'_, PyAny>> = o
                .try_iter()
                .and_then(|it| it.collect())
                .map_err(ser::Error::custom)?;
            let mut q = s.serialize_seq(Some(items.len()))?;
            for (i, v) in items.iter().enumerate() {
                q.serialize_element(&self.inner(v, format!("{}[{i}]", self.path)))?;
            }
            return q.end();
        }
        if let Ok(t) = o.cast::<PyString>() {
            return s.serialize_str(&t.to_cow().map_err(ser::Error::custom)?);
        }
        // Python ints, then numbers that are ints by value (numpy's).
        if o.is_instance_of::<PyInt>()
            || (!o.is_instance_of::<PyFloat>() && o.hasattr("__index__").unwrap_or(false))
        {
            if let Ok(i) = o.extract::<i64>() {
                return s.serialize_i64(i);
            }
            if let Ok(u) = o.extract::<u64>() {
                return s.serialize_u64(u);
            }
            return Err(self.refuse("an integer must fit in 64 bits"));
        }
        if let Ok(x) = o.extract::<f64>() {
            if !x.is_finite() {
                return Err(
                    self.refuse("every number must be finite (JSON has no NaN or infinity)")
                );
            }
            return s.serialize_f64(x);
        }
        Err(self.refuse("not a JSON value (a dict, list, str, number, bool or None)"))
    }
}
