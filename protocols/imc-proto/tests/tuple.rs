//! TupleList text: `;` (FACTS.md), `,` (the document's examples), mixed, whitespace,
//! empty pairs, and the two errors.

use imc_proto::{format_tuple_list, parse_tuple_list, TupleListError};

fn pairs(list: &[(&str, &str)]) -> Vec<(String, String)> {
    list.iter()
        .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
        .collect()
}

#[test]
fn semicolons() {
    assert_eq!(
        parse_tuple_list("Propulsion=Axis;PanTilt=Hat;Lights=Button"),
        Ok(pairs(&[
            ("Propulsion", "Axis"),
            ("PanTilt", "Hat"),
            ("Lights", "Button")
        ]))
    );
}

#[test]
fn commas_and_mixed() {
    assert_eq!(
        parse_tuple_list("Propeller=0.6,PanTilt=0.75,Lights=1"),
        Ok(pairs(&[
            ("Propeller", "0.6"),
            ("PanTilt", "0.75"),
            ("Lights", "1")
        ]))
    );
    assert_eq!(
        parse_tuple_list("a=1,b=2;c=3"),
        Ok(pairs(&[("a", "1"), ("b", "2"), ("c", "3")]))
    );
}

#[test]
fn whitespace_is_trimmed() {
    assert_eq!(
        parse_tuple_list("  Propulsion = Axis ;\tPanTilt=  Hat \n"),
        Ok(pairs(&[("Propulsion", "Axis"), ("PanTilt", "Hat")]))
    );
}

#[test]
fn empty_pairs_are_skipped() {
    assert_eq!(parse_tuple_list(""), Ok(vec![]));
    assert_eq!(parse_tuple_list("  "), Ok(vec![]));
    assert_eq!(parse_tuple_list(";;,"), Ok(vec![]));
    assert_eq!(
        parse_tuple_list(";a=1;; ;b=2;"),
        Ok(pairs(&[("a", "1"), ("b", "2")]))
    );
}

#[test]
fn values_may_be_empty_or_hold_equals() {
    assert_eq!(
        parse_tuple_list("a=;b=x=y"),
        Ok(pairs(&[("a", ""), ("b", "x=y")]))
    );
}

#[test]
fn missing_equals_and_empty_key_are_errors() {
    assert_eq!(
        parse_tuple_list("a=1;Lights"),
        Err(TupleListError::MissingEquals("Lights".into()))
    );
    assert_eq!(
        parse_tuple_list("a=1, =2"),
        Err(TupleListError::EmptyKey("=2".into()))
    );
    assert_eq!(
        parse_tuple_list("="),
        Err(TupleListError::EmptyKey("=".into()))
    );
}

#[test]
fn format_uses_semicolons_and_round_trips() {
    let list = pairs(&[
        ("Propulsion", "Axis"),
        ("PanTilt", "Hat"),
        ("Lights", "Button"),
    ]);
    let text = format_tuple_list(&list);
    assert_eq!(text, "Propulsion=Axis;PanTilt=Hat;Lights=Button");
    assert_eq!(parse_tuple_list(&text), Ok(list));
    assert_eq!(format_tuple_list::<&str, &str>(&[]), "");
    assert_eq!(format_tuple_list(&[("x", "0.5")]), "x=0.5");
}
