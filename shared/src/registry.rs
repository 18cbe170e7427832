//! Registry reads (and writes for setup).

use serde::{Deserialize, Serialize};

/// A registry value, `{"type": "dword", "data": 42}` on the wire.
///
/// A type this build does not know (a newer peer's) decodes to [`RegistryValue::Unknown`]
/// whatever its data, which serde's derive cannot do for adjacently tagged enums.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", content = "data", rename_all = "snake_case")]
pub enum RegistryValue {
    /// `REG_SZ` and `REG_EXPAND_SZ` (unexpanded).
    String(String),
    /// `REG_DWORD`.
    Dword(u32),
    /// `REG_QWORD`.
    Qword(u64),
    /// `REG_MULTI_SZ`.
    MultiString(Vec<String>),
    /// `REG_BINARY`, as bytes.
    Binary(Vec<u8>),
    Unknown,
}

impl<'de> Deserialize<'de> for RegistryValue {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<RegistryValue, D::Error> {
        #[derive(Deserialize)]
        struct Tagged {
            #[serde(rename = "type")]
            kind: String,
            #[serde(default)]
            data: serde_json::Value,
        }
        fn data<T: serde::de::DeserializeOwned, E: serde::de::Error>(
            kind: &str,
            data: serde_json::Value,
        ) -> Result<T, E> {
            serde_json::from_value(data).map_err(|err| E::custom(format!("registry value of type {kind}: {err}")))
        }
        let Tagged { kind, data: value } = Tagged::deserialize(deserializer)?;
        Ok(match kind.as_str() {
            "string" => RegistryValue::String(data(&kind, value)?),
            "dword" => RegistryValue::Dword(data(&kind, value)?),
            "qword" => RegistryValue::Qword(data(&kind, value)?),
            "multi_string" => RegistryValue::MultiString(data(&kind, value)?),
            "binary" => RegistryValue::Binary(data(&kind, value)?),
            _ => RegistryValue::Unknown,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::RegistryValue;

    fn check(json: &str, expected: Option<RegistryValue>) {
        let res = serde_json::from_str::<RegistryValue>(json).ok();
        assert_eq!(res, expected, "{json}");
    }

    #[test]
    fn values_decode_and_unknown_types_fall_back() {
        check(r#"{"type": "dword", "data": 42}"#, Some(RegistryValue::Dword(42)));
        check(r#"{"type": "string", "data": "x"}"#, Some(RegistryValue::String("x".into())));
        check(
            r#"{"type": "multi_string", "data": ["a", "b"]}"#,
            Some(RegistryValue::MultiString(vec!["a".into(), "b".into()])),
        );
        check(r#"{"type": "binary", "data": [1, 2]}"#, Some(RegistryValue::Binary(vec![1, 2])));
        check(r#"{"type": "reg_link", "data": 1}"#, Some(RegistryValue::Unknown));
        check(r#"{"type": "reg_link"}"#, Some(RegistryValue::Unknown));
        check(r#"{"type": "dword", "data": "x"}"#, None);
        check(r#"{"data": 1}"#, None);
        for value in [RegistryValue::Qword(7), RegistryValue::Unknown, RegistryValue::String("s".into())] {
            let text = serde_json::to_string(&value).unwrap();
            assert_eq!(serde_json::from_str::<RegistryValue>(&text).unwrap(), value);
        }
    }
}

/// Query of `GET /v1/registry`: `key` like `HKCU\Control Panel\Desktop`; an absent `value` is the default value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistryQuery {
    pub key: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
}

/// Body of `PUT /v1/registry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistryWrite {
    pub key: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    pub data: RegistryValue,
}

/// Answer of `GET /v1/registry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistryRead {
    pub key: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    pub data: RegistryValue,
}
