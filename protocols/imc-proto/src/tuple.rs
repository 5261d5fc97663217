//! IMC TupleList text: `key=value` pairs separated by `;` (the document's examples
//! use `,`; both are accepted).

/// A TupleList that cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TupleListError {
    #[error("pair {0:?} has no '='")]
    MissingEquals(String),
    #[error("pair {0:?} has an empty key")]
    EmptyKey(String),
}

/// Parses `Propulsion=Axis;PanTilt=Hat` (or with commas, or mixed). Whitespace around
/// keys and values is trimmed; empty pairs are skipped. A value may contain `=` (the
/// pair splits at the first one); it cannot contain `;` or `,`.
pub fn parse_tuple_list(text: &str) -> Result<Vec<(String, String)>, TupleListError> {
    text.split([';', ','])
        .map(str::trim)
        .filter(|pair| !pair.is_empty())
        .map(|pair| {
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| TupleListError::MissingEquals(pair.to_owned()))?;
            let key = key.trim();
            if key.is_empty() {
                return Err(TupleListError::EmptyKey(pair.to_owned()));
            }
            Ok((key.to_owned(), value.trim().to_owned()))
        })
        .collect()
}

/// Writes pairs separated by `;`.
pub fn format_tuple_list<K: AsRef<str>, V: AsRef<str>>(pairs: &[(K, V)]) -> String {
    let mut out = String::new();
    for (i, (k, v)) in pairs.iter().enumerate() {
        if i > 0 {
            out.push(';');
        }
        out.push_str(k.as_ref());
        out.push('=');
        out.push_str(v.as_ref());
    }
    out
}
