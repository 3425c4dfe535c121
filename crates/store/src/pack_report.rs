//! The analysis report in compact binary: the JSON tree with every fractional number
//! quantised to [`REPORT_STEP`] and arrays of such numbers delta-coded, then zstd.
//!
//! Why quantise: the report's arrays (error, velocity error, repeatability per angle) are
//! derived from lifts read at 0.1 µm; their f64 digits below 0.01 µm (0.01°, 0.01 µm/deg)
//! carry no information, and as full f64 they are 80% of a part's bytes. The quantities that
//! history queries and verdicts use are columns of `measurements`, kept exact. A read gives
//! the same JSON object as before packing with each fractional number within half a step
//! (objects' keys come back sorted, which JSON does not distinguish).

use serde_json::{Map, Number, Value};

use super::error::StoreError;
use super::pack::{Varints, put_varint as put, zigzag};

/// Quantisation of fractional numbers in a packed report: 0.01 of the number's unit (µm,
/// deg, µm/deg), a tenth of the gauge's 0.1 µm resolution.
pub const REPORT_STEP: f64 = 0.01;
const STEPS_PER_UNIT: f64 = 100.0;

const NULL: u8 = 0;
const FALSE: u8 = 1;
const TRUE: u8 = 2;
const INT: u8 = 3;
const UINT: u8 = 4;
const FRACTION: u8 = 5;
const EXACT_F64: u8 = 6;
const STRING: u8 = 7;
const ARRAY: u8 = 8;
const OBJECT: u8 = 9;
const FRACTION_ARRAY: u8 = 10;

/// Deepest nesting a packed report may have (real reports have 4); bounds the decoder's
/// recursion on damaged input.
const MAX_DEPTH: usize = 64;

fn bad(why: impl Into<String>) -> StoreError {
    StoreError::invalid("analysis_packed", why.into())
}

fn put_i(out: &mut Vec<u8>, v: i64) {
    put(out, zigzag(v));
}

/// A fractional number's steps, when it fits exactly enough (|x| < 2^50 steps).
fn steps(x: f64) -> Option<i64> {
    let s = (x * STEPS_PER_UNIT).round();
    (s.abs() < (1u64 << 50) as f64).then_some(s as i64)
}

fn is_fraction(n: &Number) -> bool {
    n.is_f64()
}

fn encode(value: &Value, out: &mut Vec<u8>) {
    match value {
        Value::Null => out.push(NULL),
        Value::Bool(false) => out.push(FALSE),
        Value::Bool(true) => out.push(TRUE),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                out.push(INT);
                put_i(out, i);
            } else if let Some(u) = n.as_u64() {
                out.push(UINT);
                put(out, u);
            } else {
                let x = n.as_f64().unwrap_or(0.0);
                match steps(x) {
                    Some(s) => {
                        out.push(FRACTION);
                        put_i(out, s);
                    }
                    None => {
                        out.push(EXACT_F64);
                        out.extend_from_slice(&x.to_le_bytes());
                    }
                }
            }
        }
        Value::String(s) => {
            out.push(STRING);
            put(out, s.len() as u64);
            out.extend_from_slice(s.as_bytes());
        }
        Value::Array(items) => {
            let fractions: Option<Vec<i64>> = (!items.is_empty())
                .then(|| {
                    items
                        .iter()
                        .map(|v| match v {
                            Value::Number(n) if is_fraction(n) => n.as_f64().and_then(steps),
                            _ => None,
                        })
                        .collect()
                })
                .flatten();
            match fractions {
                Some(s) => {
                    out.push(FRACTION_ARRAY);
                    put(out, s.len() as u64);
                    let mut prev = 0_i64;
                    for v in s {
                        put_i(out, v - prev);
                        prev = v;
                    }
                }
                None => {
                    out.push(ARRAY);
                    put(out, items.len() as u64);
                    items.iter().for_each(|v| encode(v, out));
                }
            }
        }
        Value::Object(map) => {
            out.push(OBJECT);
            put(out, map.len() as u64);
            for (k, v) in map {
                put(out, k.len() as u64);
                out.extend_from_slice(k.as_bytes());
                encode(v, out);
            }
        }
    }
}

/// The report's reader: the varints through the one reader of every packed format
/// ([`Varints`]), the tags, lengths and texts of the tree beside them.
struct Reader<'a> {
    values: Varints<'a>,
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self {
            values: Varints {
                bytes,
                field: "analysis_packed",
            },
        }
    }

    fn byte(&mut self) -> Result<u8, StoreError> {
        let (&b, rest) = self
            .values
            .bytes
            .split_first()
            .ok_or_else(|| bad("report ends early"))?;
        self.values.bytes = rest;
        Ok(b)
    }

    fn u(&mut self) -> Result<u64, StoreError> {
        self.values.next_u64()
    }

    fn i(&mut self) -> Result<i64, StoreError> {
        self.values.next_i64()
    }

    /// A length, checked against what is left (each item takes at least one byte).
    fn len(&mut self) -> Result<usize, StoreError> {
        let n = self.u()?;
        usize::try_from(n)
            .ok()
            .filter(|&n| n <= self.values.bytes.len())
            .ok_or_else(|| bad(format!("length {n} exceeds the report")))
    }

    fn text(&mut self) -> Result<String, StoreError> {
        let n = self.len()?;
        let (s, rest) = self.values.bytes.split_at(n);
        self.values.bytes = rest;
        String::from_utf8(s.to_vec()).map_err(|_| bad("text is not UTF-8"))
    }

    fn fraction(steps: i64) -> Result<Value, StoreError> {
        Number::from_f64(steps as f64 / STEPS_PER_UNIT)
            .map(Value::Number)
            .ok_or_else(|| bad("a fraction is not finite"))
    }

    fn value(&mut self, depth: usize) -> Result<Value, StoreError> {
        if depth > MAX_DEPTH {
            return Err(bad("nested too deep"));
        }
        Ok(match self.byte()? {
            NULL => Value::Null,
            FALSE => Value::Bool(false),
            TRUE => Value::Bool(true),
            INT => Value::from(self.i()?),
            UINT => Value::from(self.u()?),
            FRACTION => Self::fraction(self.i()?)?,
            EXACT_F64 => {
                let mut b = [0_u8; 8];
                for x in &mut b {
                    *x = self.byte()?;
                }
                Number::from_f64(f64::from_le_bytes(b))
                    .map(Value::Number)
                    .ok_or_else(|| bad("a number is not finite"))?
            }
            STRING => Value::String(self.text()?),
            ARRAY => {
                let n = self.len()?;
                let mut items = Vec::with_capacity(n);
                for _ in 0..n {
                    items.push(self.value(depth + 1)?);
                }
                Value::Array(items)
            }
            FRACTION_ARRAY => {
                let n = self.len()?;
                let mut items = Vec::with_capacity(n);
                let mut prev = 0_i64;
                for _ in 0..n {
                    prev = prev
                        .checked_add(self.i()?)
                        .ok_or_else(|| bad("a fraction overflows"))?;
                    items.push(Self::fraction(prev)?);
                }
                Value::Array(items)
            }
            OBJECT => {
                let n = self.len()?;
                let mut map = Map::new();
                for _ in 0..n {
                    let k = self.text()?;
                    map.insert(k, self.value(depth + 1)?);
                }
                Value::Object(map)
            }
            tag => return Err(bad(format!("unknown tag {tag}"))),
        })
    }
}

/// Packs a report (JSON text, checked by the caller).
pub(crate) fn pack_report(json: &str) -> Result<Vec<u8>, StoreError> {
    let value: Value = serde_json::from_str(json)
        .map_err(|e| StoreError::invalid("analysis_json", format!("not JSON: {e}")))?;
    let mut plain = Vec::with_capacity(json.len() / 4);
    encode(&value, &mut plain);
    super::pack::pack_bytes("analysis_packed", &plain)
}

/// The report's JSON text from [`pack_report`].
pub(crate) fn unpack_report(blob: &[u8]) -> Result<String, StoreError> {
    let plain = super::pack::unpack_bytes("analysis_packed", blob)?;
    let mut r = Reader::new(&plain);
    let value = r.value(0)?;
    if !r.values.bytes.is_empty() {
        return Err(bad("bytes after the report"));
    }
    serde_json::to_string(&value).map_err(|e| bad(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every value kind comes back; fractions within half a step, everything else exact.
    #[test]
    fn a_report_round_trips_within_half_a_step() {
        let json = r#"{"origin":"sim:A","n":204,"neg":-3,"big":18446744073709551615,
            "pass":false,"none":null,"x":-3.1556205052051185,"huge":1.5e300,
            "angle_deg":[0.0,1.0,2.0],"error_um":[0.123456,-2.5,7.77777],
            "mixed":[1,2.5,"a"],"empty":[],"band":{"from_deg":0.0,"upper_um":2.5}}"#;
        let back: Value =
            serde_json::from_str(&unpack_report(&pack_report(json).unwrap()).unwrap()).unwrap();
        let orig: Value = serde_json::from_str(json).unwrap();
        fn close(a: &Value, b: &Value, path: &str) {
            match (a, b) {
                (Value::Number(x), Value::Number(y)) if x.is_f64() => {
                    let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                    assert!(
                        (x - y).abs() <= REPORT_STEP / 2.0 + 1e-12 * x.abs(),
                        "{path}: {x} vs {y}"
                    );
                }
                (Value::Array(x), Value::Array(y)) => {
                    assert_eq!(x.len(), y.len(), "{path}");
                    for (i, (x, y)) in x.iter().zip(y).enumerate() {
                        close(x, y, &format!("{path}[{i}]"));
                    }
                }
                (Value::Object(x), Value::Object(y)) => {
                    assert_eq!(x.keys().collect::<Vec<_>>(), y.keys().collect::<Vec<_>>());
                    for (k, v) in x {
                        close(v, &y[k], &format!("{path}.{k}"));
                    }
                }
                _ => assert_eq!(a, b, "{path}"),
            }
        }
        close(&orig, &back, "");
        assert_eq!(back["x"], serde_json::json!(-3.16));
        assert_eq!(back["huge"], serde_json::json!(1.5e300));
        assert_eq!(back["big"], serde_json::json!(u64::MAX));
        assert!(back["angle_deg"][1].is_f64(), "a fraction stays a fraction");
    }

    #[test]
    fn damaged_packs_are_errors_not_panics() {
        let blob = pack_report(r#"{"a":[0.5,1.5],"b":"text"}"#).unwrap();
        let plain = super::super::pack::unpack_bytes("t", &blob).unwrap();
        for cut in 0..plain.len() {
            let mut r = Reader::new(&plain[..cut]);
            assert!(r.value(0).is_err(), "cut at {cut}");
        }
        let mut deep = [ARRAY, 1].repeat(100);
        deep.push(NULL);
        assert!(Reader::new(&deep).value(0).is_err());
        assert!(Reader::new(&[42]).value(0).is_err());
    }
}
