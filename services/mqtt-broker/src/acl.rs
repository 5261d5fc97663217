//! Topic filters (MQTT 3.1.1 §4.7) for the per-user ACLs: checking a configured
//! filter, matching a PUBLISH topic, and deciding whether a SUBSCRIBE filter stays
//! within an allowed one. Pure.

/// Why `filter` is not an MQTT topic filter.
pub fn valid_filter(filter: &str) -> Result<(), &'static str> {
    if filter.is_empty() {
        return Err("empty");
    }
    if filter.len() > usize::from(u16::MAX) {
        return Err("longer than 65535 bytes");
    }
    if filter.contains('\0') {
        return Err("contains NUL");
    }
    let levels: Vec<&str> = filter.split('/').collect();
    for (i, level) in levels.iter().enumerate() {
        match *level {
            "#" if i + 1 != levels.len() => return Err("`#` must be the last level"),
            "#" | "+" => {}
            l if l.contains(['#', '+']) => return Err("`+` and `#` must fill a whole level"),
            _ => {}
        }
    }
    Ok(())
}

/// Why `topic` is not a topic name a client may publish to.
pub fn valid_topic(topic: &str) -> Result<(), &'static str> {
    if topic.is_empty() {
        return Err("empty");
    }
    if topic.contains(['#', '+', '\0']) {
        return Err("contains a wildcard or NUL");
    }
    Ok(())
}

/// True if topic name `topic` matches `filter` (a [`valid_filter`]). Topics
/// starting with `$` are not matched by a leading wildcard (§4.7.2).
pub fn matches(filter: &str, topic: &str) -> bool {
    if topic.starts_with('$') && filter.starts_with(['+', '#']) {
        return false;
    }
    let mut f = filter.split('/');
    let mut t = topic.split('/');
    loop {
        match (f.next(), t.next()) {
            (Some("#"), _) => return true,
            (Some("+"), Some(_)) => {}
            (Some(a), Some(b)) if a == b => {}
            (None, None) => return true,
            _ => return false,
        }
    }
}

/// True if every topic that `requested` matches is matched by `allowed` (both
/// valid filters): a subscription within what the user may read.
pub fn covers(allowed: &str, requested: &str) -> bool {
    if requested.starts_with('$') && allowed.starts_with(['+', '#']) {
        // `#` does not reach `$SYS/...`; a `$` topic needs a rule naming it.
        return false;
    }
    let mut a = allowed.split('/');
    let mut r = requested.split('/');
    loop {
        match (a.next(), r.next()) {
            (Some("#"), _) => return true,
            // A wildcard asks for more than any literal or `+` grants.
            (Some(_), Some("#")) => return false,
            (Some("+"), Some(_)) => {}
            (Some(x), Some(y)) if x == y && y != "+" => {}
            (None, None) => return true,
            _ => return false,
        }
    }
}

/// True if `topic` matches one of `filters`.
pub fn any_matches(filters: &[String], topic: &str) -> bool {
    filters.iter().any(|f| matches(f, topic))
}

/// True if `requested` is within one of `filters`.
pub fn any_covers(filters: &[String], requested: &str) -> bool {
    filters.iter().any(|f| covers(f, requested))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filters_are_checked() {
        for ok in ["#", "+", "a/+/b", "a/#", "thing/product/+/drc/down", "/"] {
            assert_eq!(valid_filter(ok), Ok(()), "{ok}");
        }
        for bad in ["", "a/#/b", "a#", "a/b+", "+a", "a\0"] {
            assert!(valid_filter(bad).is_err(), "{bad}");
        }
        assert!(valid_topic("a/+").is_err());
        assert!(valid_topic("a/b").is_ok());
    }

    #[test]
    fn topics_match_filters() {
        assert!(matches(
            "thing/product/+/services",
            "thing/product/SN1/services"
        ));
        assert!(!matches(
            "thing/product/+/services",
            "thing/product/SN1/drc/down"
        ));
        assert!(matches("thing/product/SN1/#", "thing/product/SN1/drc/down"));
        assert!(matches("thing/product/SN1/#", "thing/product/SN1"));
        assert!(!matches(
            "thing/product/SN1/#",
            "thing/product/SN2/services"
        ));
        assert!(matches("#", "anything/at/all"));
        assert!(!matches("#", "$SYS/broker"));
        assert!(matches("$SYS/#", "$SYS/broker"));
        assert!(!matches("a/b", "a/b/c"));
        assert!(!matches("a/b/c", "a/b"));
    }

    #[test]
    fn subscriptions_stay_within_the_allowed_filters() {
        let allowed = "thing/product/+/services_reply";
        assert!(covers(allowed, "thing/product/SN1/services_reply"));
        assert!(covers(allowed, "thing/product/+/services_reply"));
        assert!(!covers(allowed, "thing/product/#"));
        assert!(!covers(allowed, "thing/product/+/+"));
        assert!(!covers(allowed, "#"));
        assert!(!covers(
            "thing/product/SN1/services",
            "thing/product/+/services"
        ));
        assert!(covers("thing/#", "thing/product/+/drc/#"));
        assert!(covers("thing/#", "thing"));
        assert!(!covers("thing/product", "thing/product/x"));
        assert!(covers("#", "#"));
        assert!(!covers("#", "$SYS/broker"));
    }
}
