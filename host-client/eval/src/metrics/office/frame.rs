//! The part of pandas (2.0, as upstream pins it) that upstream's `sheet_data`
//! rule relies on: `pd.read_excel(book, sheet)` (first row as header,
//! per-column type inference), `DataFrame.round(n)` and `DataFrame.equals`.
//!
//! What matters for equality is reproduced: the table's extent (trailing empty
//! rows and columns trimmed, rows padded to the widest), header labels
//! (`Unnamed: i`, `.1` suffixes for duplicates), column dtypes (`int64`,
//! `float64`, `bool`, `datetime64`, `timedelta64`, `object`: `equals` fails
//! on a dtype mismatch even when values agree), NaN placement, and numeric
//! strings becoming numbers. Dates keep their exact value (to openpyxl's
//! millisecond), so the same day at another time, or a date typed as a plain
//! number, is a different value. It is not a data-frame library.

use super::xlsx::{Moment, Value};

/// The strings pandas reads as NaN by default.
const NA_STRINGS: &[&str] = &[
    "", "#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "-nan", "1.#IND", "1.#QNAN", "<NA>", "N/A", "NA",
    "NULL", "NaN", "None", "n/a", "nan", "null",
];

/// One element of an `object` column or a header label, with Python's `==`.
#[derive(Debug, Clone)]
pub(super) enum PyObj {
    NaN,
    Int(i64),
    Float(f64),
    Bool(bool),
    Str(String),
    /// A Python `datetime`, `time` or `timedelta` (openpyxl's date cells).
    Moment(Moment),
}

impl PartialEq for PyObj {
    fn eq(&self, other: &PyObj) -> bool {
        use PyObj::*;
        match (self, other) {
            (NaN, NaN) => true,
            (Str(a), Str(b)) => a == b,
            (Moment(a), Moment(b)) => a == b,
            (Moment(_), _) | (_, Moment(_)) => false,
            (a, b) => match (a.number(), b.number()) {
                (Some(x), Some(y)) => x == y,
                _ => false,
            },
        }
    }
}

impl PyObj {
    fn number(&self) -> Option<f64> {
        match self {
            PyObj::Int(i) => Some(*i as f64),
            PyObj::Float(f) => Some(*f),
            PyObj::Bool(b) => Some(f64::from(u8::from(*b))),
            _ => None,
        }
    }

    fn label(&self) -> String {
        match self {
            PyObj::NaN => "nan".into(),
            PyObj::Int(i) => i.to_string(),
            PyObj::Float(f) => format!("{f:?}"),
            PyObj::Bool(b) => if *b { "True" } else { "False" }.into(),
            PyObj::Str(s) => s.clone(),
            PyObj::Moment(m) => moment_label(*m),
        }
    }
}

/// A column with its inferred dtype.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Column {
    Int(Vec<i64>),
    /// NaN is a missing value.
    Float(Vec<f64>),
    Bool(Vec<bool>),
    /// `datetime64[ns]`, milliseconds since 1899-12-30; `None` is NaT.
    DateTime(Vec<Option<i64>>),
    /// `timedelta64[ns]`, milliseconds; `None` is NaT.
    Duration(Vec<Option<i64>>),
    Object(Vec<PyObj>),
}

/// A sheet read as `pd.read_excel` reads it.
#[derive(Debug, Clone)]
pub(super) struct Frame {
    pub(super) labels: Vec<PyObj>,
    pub(super) columns: Vec<Column>,
    pub(super) rows: usize,
}

/// A cell as pandas' openpyxl reader converts it (`_convert_cell`).
fn convert(value: &Value) -> PyObj {
    match value {
        Value::Empty => PyObj::Str(String::new()),
        Value::Error => PyObj::NaN,
        Value::Bool(b) => PyObj::Bool(*b),
        Value::Text(s) => PyObj::Str(s.clone()),
        Value::Date(m) => PyObj::Moment(*m),
        Value::Number(n) => {
            // pandas returns an int when the float is integral.
            if n.fract() == 0.0 && n.abs() < 9.0e15 {
                PyObj::Int(*n as i64)
            } else {
                PyObj::Float(*n)
            }
        }
    }
}

fn is_blank(obj: &PyObj) -> bool {
    matches!(obj, PyObj::Str(s) if s.is_empty())
}

impl Frame {
    /// Builds the frame from a grid of cell values (row-major, from A1).
    pub(super) fn from_grid(grid: &[Vec<Value>]) -> Frame {
        let mut data: Vec<Vec<PyObj>> = Vec::with_capacity(grid.len());
        let mut last_with_data = None;
        for (i, row) in grid.iter().enumerate() {
            let mut converted: Vec<PyObj> = row.iter().map(convert).collect();
            while converted.last().is_some_and(is_blank) {
                converted.pop();
            }
            if !converted.is_empty() {
                last_with_data = Some(i);
            }
            data.push(converted);
        }
        data.truncate(last_with_data.map_or(0, |i| i + 1));
        let width = data.iter().map(Vec::len).max().unwrap_or(0);
        for row in &mut data {
            row.resize(width, PyObj::Str(String::new()));
        }
        // Empty and whitespace-only rows inside the table stay rows (NaN and
        // the text itself), one-column tables included: pandas keeps them.
        if data.is_empty() {
            return Frame { labels: Vec::new(), columns: Vec::new(), rows: 0 };
        }
        let header = data.remove(0);
        let labels = dedup_labels(header);
        let rows = data.len();
        let columns = (0..width)
            .map(|j| {
                let values: Vec<PyObj> = data.iter().map(|row| row[j].clone()).collect();
                infer_column(values)
            })
            .collect();
        Frame { labels, columns, rows }
    }

    /// `DataFrame.round(decimals)`: float columns only.
    pub(super) fn round(&mut self, decimals: i32) {
        let scale = 10f64.powi(decimals);
        for column in &mut self.columns {
            if let Column::Float(values) = column {
                for v in values.iter_mut() {
                    if v.is_finite() {
                        *v = (*v * scale).round_ties_even() / scale;
                    }
                }
            }
        }
    }

    /// `DataFrame.equals`: same labels, same shape, same dtypes, equal values (NaN equal to NaN).
    pub(super) fn equals(&self, other: &Frame) -> bool {
        self.rows == other.rows
            && self.labels == other.labels
            && self.columns.len() == other.columns.len()
            && self.columns.iter().zip(&other.columns).all(|(a, b)| match (a, b) {
                (Column::Float(x), Column::Float(y)) => {
                    x.iter().zip(y).all(|(p, q)| p == q || (p.is_nan() && q.is_nan()))
                }
                _ => a == b,
            })
    }
}

/// Python's `str()` of a date header, which duplicate-label suffixes build on.
fn moment_label(moment: Moment) -> String {
    const DAY: i64 = 86_400_000;
    let clock = |ms: i64| {
        let (s, frac) = (ms / 1000, ms % 1000);
        let text = format!("{:02}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60);
        if frac == 0 {
            text
        } else {
            format!("{text}.{:06}", frac * 1000)
        }
    };
    match moment {
        Moment::DateTime(ms) => {
            // Days since 1899-12-30 are days since 1970 shifted by 25 569.
            let (y, m, d) = arena_shared::calendar::civil_from_days(ms.div_euclid(DAY) - 25_569);
            format!("{y:04}-{m:02}-{d:02} {}", clock(ms.rem_euclid(DAY)))
        }
        Moment::Time(ms) => clock(ms),
        Moment::Duration(ms) => {
            let days = ms.div_euclid(DAY);
            let rest = clock(ms.rem_euclid(DAY));
            match days {
                0 => rest,
                1 | -1 => format!("{days} day, {rest}"),
                _ => format!("{days} days, {rest}"),
            }
        }
    }
}

/// Header labels: blanks become `Unnamed: i`, repeated labels get `.1`, `.2`.
fn dedup_labels(header: Vec<PyObj>) -> Vec<PyObj> {
    let mut labels: Vec<PyObj> = header
        .into_iter()
        .enumerate()
        .map(|(i, obj)| if is_blank(&obj) { PyObj::Str(format!("Unnamed: {i}")) } else { obj })
        .collect();
    let mut seen: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for label in &mut labels {
        let key = label.label();
        let count = seen.entry(key.clone()).or_insert(0);
        if *count > 0 {
            let mut n = *count;
            let mut renamed = format!("{key}.{n}");
            while seen.contains_key(&renamed) {
                n += 1;
                renamed = format!("{key}.{n}");
            }
            *seen.entry(key).or_insert(0) = n + 1;
            seen.insert(renamed.clone(), 1);
            *label = PyObj::Str(renamed);
        } else {
            *count = 1;
        }
    }
    labels
}

/// A string as pandas' numeric conversion parses it.
fn parse_numeric(s: &str) -> Option<PyObj> {
    let t = s.trim();
    if t.is_empty() || t.eq_ignore_ascii_case("inf") || t.eq_ignore_ascii_case("nan") {
        return None;
    }
    let plain = t.strip_prefix(['+', '-']).unwrap_or(t);
    if !plain.chars().next().is_some_and(|c| c.is_ascii_digit() || c == '.') {
        return None;
    }
    if plain.chars().all(|c| c.is_ascii_digit()) {
        if let Ok(i) = t.parse::<i64>() {
            return Some(PyObj::Int(i));
        }
    }
    t.parse::<f64>().ok().map(PyObj::Float)
}

/// Column type inference (`maybe_convert_numeric`, then booleans, then the
/// DataFrame constructor's datetime/timedelta inference, else object).
fn infer_column(values: Vec<PyObj>) -> Column {
    if values.is_empty() {
        return Column::Object(values);
    }
    let values: Vec<PyObj> = values
        .into_iter()
        .map(|v| match v {
            PyObj::Str(s) if NA_STRINGS.contains(&s.as_str()) => PyObj::NaN,
            other => other,
        })
        .collect();
    if let Some(column) = numeric_column(&values) {
        return column;
    }
    let bool_of = |v: &PyObj| match v {
        PyObj::Bool(b) => Some(*b),
        PyObj::Str(s) if matches!(s.as_str(), "True" | "TRUE" | "true") => Some(true),
        PyObj::Str(s) if matches!(s.as_str(), "False" | "FALSE" | "false") => Some(false),
        _ => None,
    };
    if let Some(bools) = values.iter().map(bool_of).collect::<Option<Vec<bool>>>() {
        return Column::Bool(bools);
    }
    // A column of datetimes (or of timedeltas) with only NaN besides becomes
    // datetime64 (timedelta64) with NaT; times of day stay Python objects.
    let moments = |want: fn(&Moment) -> Option<i64>| -> Option<Vec<Option<i64>>> {
        let mut any = false;
        let column = values
            .iter()
            .map(|v| match v {
                PyObj::NaN => Some(None),
                PyObj::Moment(m) => {
                    any = true;
                    want(m).map(Some)
                }
                _ => None,
            })
            .collect::<Option<Vec<_>>>()?;
        any.then_some(column)
    };
    if let Some(column) = moments(|m| if let Moment::DateTime(ms) = m { Some(*ms) } else { None }) {
        return Column::DateTime(column);
    }
    if let Some(column) = moments(|m| if let Moment::Duration(ms) = m { Some(*ms) } else { None }) {
        return Column::Duration(column);
    }
    Column::Object(values)
}

fn numeric_column(values: &[PyObj]) -> Option<Column> {
    let mut parsed = Vec::with_capacity(values.len());
    let (mut seen_nan, mut seen_float, mut seen_int) = (false, false, false);
    for v in values {
        let p = match v {
            PyObj::Str(s) => parse_numeric(s)?,
            PyObj::Moment(_) => return None,
            other => other.clone(),
        };
        match p {
            PyObj::NaN => seen_nan = true,
            PyObj::Float(_) => seen_float = true,
            PyObj::Int(_) => seen_int = true,
            _ => {}
        }
        parsed.push(p);
    }
    if seen_nan || seen_float {
        Some(Column::Float(parsed.iter().map(|p| p.number().unwrap_or(f64::NAN)).collect()))
    } else if seen_int {
        Some(Column::Int(parsed.iter().map(|p| p.number().map_or(0, |f| f as i64)).collect()))
    } else {
        Some(Column::Bool(parsed.iter().map(|p| matches!(p, PyObj::Bool(true))).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn n(v: f64) -> Value {
        Value::Number(v)
    }
    fn t(s: &str) -> Value {
        Value::Text(s.into())
    }

    #[test]
    fn header_labels_and_extent_follow_pandas() {
        let grid = vec![
            vec![t("a"), Value::Empty, t("a"), Value::Empty],
            vec![n(1.0), n(2.0), n(3.0), Value::Empty],
            vec![Value::Empty, Value::Empty, Value::Empty, Value::Empty],
        ];
        let frame = Frame::from_grid(&grid);
        assert_eq!(
            frame.labels,
            vec![PyObj::Str("a".into()), PyObj::Str("Unnamed: 1".into()), PyObj::Str("a.1".into())]
        );
        assert_eq!(frame.rows, 1);
        assert_eq!(frame.columns[0], Column::Int(vec![1]));
    }

    #[test]
    fn dtypes_decide_equality() {
        let ints = Frame::from_grid(&[vec![t("x")], vec![n(1.0)], vec![n(2.0)]]);
        let floats = Frame::from_grid(&[vec![t("x")], vec![n(1.0)], vec![n(2.5)]]);
        let strings = Frame::from_grid(&[vec![t("x")], vec![t("001")], vec![t("2")]]);
        assert!(!ints.equals(&floats));
        // Numeric text becomes numbers, as pandas' numeric conversion does.
        assert_eq!(strings.columns[0], Column::Int(vec![1, 2]));
        let mixed = Frame::from_grid(&[vec![t("x")], vec![t("a")], vec![n(2.0)]]);
        assert_eq!(mixed.columns[0], Column::Object(vec![PyObj::Str("a".into()), PyObj::Int(2)]));
        let date = |serial| Value::Date(Moment::from_serial(serial, false).unwrap());
        let dates = Frame::from_grid(&[vec![t("d")], vec![date(45000.75)], vec![Value::Empty]]);
        assert_eq!(dates.columns[0], Column::DateTime(vec![Some(45000 * 86_400_000 + 64_800_000)]));
        let with_nat = Frame::from_grid(&[vec![t("d")], vec![date(45000.0)], vec![Value::Empty], vec![date(1.0)]]);
        assert_eq!(with_nat.columns[0], Column::DateTime(vec![Some(45000 * 86_400_000), None, Some(2 * 86_400_000)]));
        let times = Frame::from_grid(&[vec![t("t")], vec![date(0.5)]]);
        assert_eq!(times.columns[0], Column::Object(vec![PyObj::Moment(Moment::Time(43_200_000))]));
        let spans = Frame::from_grid(&[vec![t("t")], vec![Value::Date(Moment::from_serial(1.5, true).unwrap())]]);
        assert_eq!(spans.columns[0], Column::Duration(vec![Some(129_600_000)]));
        let label = Frame::from_grid(&[vec![date(45293.5), date(45293.5)], vec![n(1.0), n(2.0)]]);
        assert_eq!(
            label.labels,
            vec![
                PyObj::Moment(Moment::DateTime(45293 * 86_400_000 + 43_200_000)),
                PyObj::Str("2024-01-02 12:00:00.1".into())
            ]
        );
    }

    #[test]
    fn rounding_is_half_even_at_the_scaled_value() {
        let mut a = Frame::from_grid(&[vec![t("x")], vec![n(1.000_04)], vec![n(f64::from(2))]]);
        let mut b = Frame::from_grid(&[vec![t("x")], vec![n(1.000_01)], vec![n(2.000_000_1)]]);
        a.round(4);
        b.round(4);
        assert!(a.equals(&b));
    }
}
