//! What every handler enforces on its input, declared in the OpenAPI
//! document once for all routes rather than field by field: a schema-driven
//! client (schemathesis, a generated client) must find every request the
//! spec allows accepted and every one it forbids refused.
//!
//! - text: no field, query parameter or object key may hold a control
//!   character ([`super::extract::parse_json`], [`super::extract::ApiQuery`]),
//!   so every request-side string without an enum or a pattern of its own
//!   gets [`TEXT_PATTERN`], and every object that takes keys it does not
//!   list gets it as `propertyNames`;
//! - integers: serde reads `i64` and `u64` only, so their bounds are
//!   declared where a field has none of its own; a path id is digits only
//!   ([`super::extract::Id`]), 1 or more;
//! - errors: a route with a query string or a body documents the answers
//!   its extractors give (400, 408, 413, 415, 422).
//!
//! Response schemas are left alone: only the components that request
//! bodies and parameters reference are touched (the two sets share no
//! string or object schema but the `ApproachIn` enum).

use std::collections::BTreeSet;

use utoipa::openapi::path::{Operation, ParameterIn};
use utoipa::openapi::schema::{AdditionalProperties, ArrayItems, Schema, SchemaType, Type};
use utoipa::openapi::{OpenApi, RefOr};

/// A text without control characters (`char::is_control`: U+0000-U+001F,
/// U+007F-U+009F), as every text field and query parameter must be.
pub const TEXT_PATTERN: &str = r"^[^\x00-\x1F\x7F-\x9F]*$";

/// A text as [`TEXT_PATTERN`] with at least one character that is not
/// white space: a name or reason the handler trims and refuses when empty.
pub const NON_BLANK_PATTERN: &str =
    r"^[^\x00-\x1F\x7F-\x9F]*[^\s\x00-\x1F\x7F-\x9F][^\x00-\x1F\x7F-\x9F]*$";

/// A date or a UTC time as `store::time::normalize_bound` takes it
/// (`2027-06-30`, `2027-06-30T12:00:00Z`, `2027-06-30T12:00:00.5Z`), with
/// the days of each month and leap years.
pub const DATE_OR_TIME_PATTERN: &str = concat!(
    "^(?:[0-9]{4}-(?:0[1-9]|1[0-2])-(?:0[1-9]|1[0-9]|2[0-8])",
    "|[0-9]{4}-(?:0[13-9]|1[0-2])-(?:29|30)",
    "|[0-9]{4}-(?:0[13578]|1[02])-31",
    "|(?:[0-9]{2}(?:0[48]|[2468][048]|[13579][26])|(?:[02468][048]|[13579][26])00)-02-29)",
    "(?:T(?:[01][0-9]|2[0-3]):[0-5][0-9]:[0-5][0-9](?:\\.[0-9]+)?Z)?$"
);

/// A site a key is limited to: [`NON_BLANK_PATTERN`] without commas.
pub const SITE_PATTERN: &str =
    r"^[^,\x00-\x1F\x7F-\x9F]*[^,\s\x00-\x1F\x7F-\x9F][^,\x00-\x1F\x7F-\x9F]*$";

/// Request fields (component, property) whose text the handler trims and
/// refuses when blank.
const NON_BLANK_FIELDS: &[(&str, &str)] = &[
    ("CreateKey", "name"),
    ("CreateRobot", "serial_number"),
    ("Activate", "reason"),
    ("Rollback", "reason"),
];

/// Request fields (component, property) that take a date or a UTC time.
const DATE_FIELDS: &[(&str, &str)] = &[("CreateKey", "expires_at")];

/// Query parameters that take a date or a UTC time (`GET /calibrations`).
const DATE_PARAMS: &[&str] = &["from", "to"];

/// Declare, on `doc`, the constraints listed in the module documentation.
pub(super) fn declare(doc: &mut OpenApi) {
    let mut request_components = BTreeSet::new();
    for item in doc.paths.paths.values_mut() {
        for op in operations(item) {
            let mut has_query = false;
            for p in op.parameters.iter_mut().flatten() {
                let RefOr::T(p) = p else { continue };
                has_query |= matches!(p.parameter_in, ParameterIn::Query);
                if let Some(s) = &mut p.schema {
                    if matches!(p.parameter_in, ParameterIn::Query)
                        && DATE_PARAMS.contains(&p.name.as_str())
                    {
                        set_pattern(s, DATE_OR_TIME_PATTERN);
                    }
                    referenced(s, &mut request_components);
                    constrain(s);
                    if matches!(p.parameter_in, ParameterIn::Path) && p.name == "id" {
                        path_id(s);
                    }
                }
            }
            let mut has_body = false;
            if let Some(RefOr::T(body)) = &mut op.request_body {
                has_body = true;
                for (content_type, content) in &mut body.content {
                    // CSV bodies are text with line breaks; their rows are
                    // checked as data, not as one text field.
                    let (RefOr::T(content), true) = (content, content_type == "application/json")
                    else {
                        continue;
                    };
                    if let Some(s) = &mut content.schema {
                        referenced(s, &mut request_components);
                        constrain(s);
                    }
                }
            }
            document_errors(op, has_query, has_body);
        }
    }
    // The components request schemas reference, and those they reference.
    let Some(components) = &mut doc.components else {
        return;
    };
    let mut todo: Vec<String> = request_components.iter().cloned().collect();
    while let Some(name) = todo.pop() {
        if let Some(s) = components.schemas.get(&name) {
            let mut more = BTreeSet::new();
            referenced(s, &mut more);
            for m in more {
                if request_components.insert(m.clone()) {
                    todo.push(m);
                }
            }
        }
    }
    for (fields, pattern) in [
        (NON_BLANK_FIELDS, NON_BLANK_PATTERN),
        (DATE_FIELDS, DATE_OR_TIME_PATTERN),
    ] {
        for (component, property) in fields {
            if let Some(p) = property_of(components, component, property) {
                set_pattern(p, pattern);
            }
        }
    }
    // rig.json's anchors are points (utoipa gives an array of arrays no
    // bounds on the inner one).
    if let Some(RefOr::T(Schema::Array(a))) = property_of(components, "RigJson", "anchors_mm")
        && let ArrayItems::RefOrSchema(item) = &mut a.items
        && let RefOr::T(Schema::Array(point)) = item.as_mut()
    {
        point.min_items = Some(3);
        point.max_items = Some(3);
    }
    if let Some(RefOr::T(Schema::Object(o))) = property_of(components, "CreateKey", "role") {
        o.enum_values = Some(
            super::auth::Role::ALL
                .iter()
                .map(|r| r.as_str().into())
                .collect(),
        );
    }
    if let Some(RefOr::T(Schema::Array(a))) = property_of(components, "CreateKey", "sites")
        && let ArrayItems::RefOrSchema(item) = &mut a.items
        && let RefOr::T(Schema::Object(o)) = item.as_mut()
    {
        o.pattern = Some(SITE_PATTERN.into());
        o.min_length = Some(1);
        o.max_length = Some(100);
    }
    for name in &request_components {
        if let Some(s) = components.schemas.get_mut(name) {
            constrain(s);
        }
    }
}

/// The schema of `component`'s `property`.
fn property_of<'a>(
    components: &'a mut utoipa::openapi::Components,
    component: &str,
    property: &str,
) -> Option<&'a mut RefOr<Schema>> {
    match components.schemas.get_mut(component)? {
        RefOr::T(Schema::Object(o)) => o.properties.get_mut(property),
        _ => None,
    }
}

/// Give a string schema its pattern.
fn set_pattern(s: &mut RefOr<Schema>, pattern: &str) {
    if let RefOr::T(Schema::Object(o)) = s {
        o.pattern = Some(pattern.into());
    }
}

/// The operations of a path item.
fn operations(item: &mut utoipa::openapi::PathItem) -> impl Iterator<Item = &mut Operation> {
    [
        &mut item.get,
        &mut item.post,
        &mut item.put,
        &mut item.patch,
        &mut item.delete,
    ]
    .into_iter()
    .filter_map(|o| o.as_mut())
}

/// Add to `out` the component names `s` references (`#/components/schemas/X`).
fn referenced(s: &RefOr<Schema>, out: &mut BTreeSet<String>) {
    match s {
        RefOr::Ref(r) => {
            if let Some(name) = r.ref_location.strip_prefix("#/components/schemas/") {
                out.insert(name.to_string());
            }
        }
        RefOr::T(Schema::Object(o)) => {
            o.properties.values().for_each(|p| referenced(p, out));
            if let Some(AdditionalProperties::RefOr(a)) = o.additional_properties.as_deref() {
                referenced(a, out);
            }
        }
        RefOr::T(Schema::Array(a)) => {
            if let ArrayItems::RefOrSchema(i) = &a.items {
                referenced(i, out);
            }
        }
        RefOr::T(Schema::OneOf(x)) => x.items.iter().for_each(|i| referenced(i, out)),
        RefOr::T(Schema::AllOf(x)) => x.items.iter().for_each(|i| referenced(i, out)),
        RefOr::T(Schema::AnyOf(x)) => x.items.iter().for_each(|i| referenced(i, out)),
        RefOr::T(_) => {}
    }
}

/// Does the schema type include `t`?
fn has_type(st: &SchemaType, t: Type) -> bool {
    match st {
        SchemaType::Type(x) => *x == t,
        SchemaType::Array(xs) => xs.contains(&t),
        SchemaType::AnyValue => false,
    }
}

/// The constraints of the module documentation on one request schema and
/// everything inline in it.
fn constrain(s: &mut RefOr<Schema>) {
    let RefOr::T(s) = s else { return };
    match s {
        Schema::Object(o) => {
            if has_type(&o.schema_type, Type::String)
                && o.enum_values.is_none()
                && o.pattern.is_none()
            {
                o.pattern = Some(TEXT_PATTERN.into());
            }
            if has_type(&o.schema_type, Type::Integer) {
                // utoipa writes a u64 as int64 with minimum 0 (a signed
                // field with minimum 0 gives its maximum itself).
                let unsigned = match o.minimum {
                    Some(utoipa::Number::Int(0) | utoipa::Number::UInt(0)) => true,
                    Some(utoipa::Number::Float(f)) => f == 0.0,
                    _ => false,
                };
                if o.minimum.is_none() && o.exclusive_minimum.is_none() {
                    o.minimum = Some(if unsigned {
                        utoipa::Number::UInt(0)
                    } else {
                        utoipa::Number::Int(i64::MIN as isize)
                    });
                }
                if o.maximum.is_none() && o.exclusive_maximum.is_none() {
                    o.maximum = Some(if unsigned {
                        utoipa::Number::UInt(u64::MAX as usize)
                    } else {
                        utoipa::Number::Int(i64::MAX as isize)
                    });
                }
            }
            let extras_allowed = !matches!(
                o.additional_properties.as_deref(),
                Some(AdditionalProperties::FreeForm(false))
            );
            if has_type(&o.schema_type, Type::Object)
                && extras_allowed
                && o.property_names.is_none()
            {
                o.property_names = Some(Box::new(Schema::Object(
                    utoipa::openapi::ObjectBuilder::new()
                        .schema_type(Type::String)
                        .pattern(Some(TEXT_PATTERN))
                        .build(),
                )));
            }
            o.properties.values_mut().for_each(constrain);
            if let Some(AdditionalProperties::RefOr(a)) = o.additional_properties.as_deref_mut() {
                constrain(a);
            }
        }
        Schema::Array(a) => {
            if let ArrayItems::RefOrSchema(i) = &mut a.items {
                constrain(i);
            }
        }
        Schema::OneOf(x) => x.items.iter_mut().for_each(constrain),
        Schema::AllOf(x) => x.items.iter_mut().for_each(constrain),
        Schema::AnyOf(x) => x.items.iter_mut().for_each(constrain),
        _ => {}
    }
}

/// A path id: digits only, so 0 or more; ids start at 1.
fn path_id(s: &mut RefOr<Schema>) {
    if let RefOr::T(Schema::Object(o)) = s {
        o.minimum = Some(utoipa::Number::Int(1));
        o.maximum = Some(utoipa::Number::Int(i64::MAX as isize));
    }
}

/// The answers of the extractors, where the handler's own list lacks them.
fn document_errors(op: &mut Operation, has_query: bool, has_body: bool) {
    let mut add = |status: &str, description: &str| {
        op.responses
            .responses
            .entry(status.into())
            .or_insert_with(|| super::error_response(description.into()).into());
    };
    if has_query || has_body {
        add(
            "400",
            "Malformed request: a query parameter of the wrong type, malformed JSON",
        );
        add(
            "422",
            "A field or query parameter out of its declared range or pattern (a control character in any text, named in `field`), or a value the route refuses",
        );
    }
    if has_body {
        add("408", super::error::BODY_TIMEOUT_408);
        add("413", super::error::BODY_TOO_LARGE_413);
        add("415", "A body that is not of a documented content type");
    }
}
