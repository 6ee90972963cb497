"""Hooks of tests/api/schemathesis.sh (SCHEMATHESIS_HOOKS).

Two things a schema cannot carry, and only these:

1. Which ids exist. A body naming a robot, model, rig or calibration that
   does not exist is refused 422 naming the field (as a path id that does
   not exist is 404, which schemathesis expects). `before_call` points
   those fields at the resources the script seeded (ids 1), so that the rest
   of each body is what gets tested. Only an integer (or an integral
   number) within int64 is replaced: a value of the wrong type or out of range stays, and stays a
   negative case. Schemathesis revalidates a case a hook changed.

2. Rules across fields, or between the body and the stored robot or rig,
   that JSON Schema cannot state (see CROSS_FIELD). `filter_failure` drops a
   "schema-valid request rejected" (ST202) failure only when the 422 names
   one of these rules, by its field and the words of its message; any
   other 422 to a spec-valid request still fails the run. The run's summary
   counts what was dropped.
"""

import atexit
import collections
import re
import sys

import schemathesis

# What filter_failure dropped, by operation and rule: said at the end.
DROPPED = collections.Counter()


@atexit.register
def _say_dropped():
    for (operation, rule), n in sorted(DROPPED.items()):
        print(f"dropped by filter_failure: {n:4} {operation}: {rule}", file=sys.stderr)

I64 = (-(2**63), 2**63 - 1)

# Body fields naming a stored resource, by operation: the seeded id.
REFERENCES = {
    "POST /robots": {"model_id": 1},
    "POST /sessions": {"robot_id": 1, "rig_id": 1},
    "POST /robots/{id}/activate": {"calibration_id": 1},
    "POST /plans": {"model_id": 1, "robot_id": 1, "rig_id": 1},
    "POST /compensate": {"robot_id": 1, "calibration_id": 1},
}


def _replaceable(v):
    # An integer, or an integral number (JSON Schema's integer: 5.0).
    if isinstance(v, float) and v.is_integer():
        v = int(v)
    return isinstance(v, int) and not isinstance(v, bool) and I64[0] <= v <= I64[1]


@schemathesis.hook
def before_call(ctx, case, **kwargs):
    fields = REFERENCES.get(case.operation.label)
    if not fields:
        return
    if isinstance(case.body, dict):
        for name, seeded in fields.items():
            if _replaceable(case.body.get(name)):
                case.body[name] = seeded
    # Calibration 1 is robot 1's: activate it on robot 1.
    if case.operation.label == "POST /robots/{id}/activate" and case.path_parameters:
        id_ = case.path_parameters.get("id")
        if _replaceable(id_) or (isinstance(id_, str) and id_.isdigit()):
            case.path_parameters["id"] = 1


# Spec-valid requests the handler rightly refuses, by operation: (field as
# a regular expression, words of the message). Each is a rule between
# fields, or between the request and what is stored, that JSON Schema
# cannot state.
CROSS_FIELD = {
    "POST /models": [
        # A joint's limits in order.
        (r"joints\[\d+\]\.q_min_deg", "must be below q_max_deg"),
        # One link per joint.
        (r"links", "give one per joint"),
    ],
    "POST /rigs": [
        # Anchors: none (a point instrument) or 3 and more, apart and not
        # on one line; one name per anchor; r_mm given with anchors.
        (r"anchors_mm", "at least 3 are needed"),
        (r"anchors_mm\[\d+\]", "coincides with"),
        (r"anchors_mm", "lie on one line"),
        (r"anchor_names", "names for"),
        (r"r_mm|\.", "missing field `r_mm`"),
    ],
    "POST /plans": [
        # model_id or robot_id, exactly one.
        (r"robot_id", "not both"),
        (r"model_id", "give the robot model"),
    ],
    "POST /keys": [
        # An admin key is not limited to sites.
        (r"sites", "not limited to sites"),
    ],
    "POST /compensate": [
        # Options go in the JSON body or, with a CSV body, in the query
        # string: an OpenAPI parameter cannot depend on the content type.
        (r"robot_id|calibration_id|orientation|temp_c|payload_kg|approach", "not the query string"),
        # target or targets, exactly one; q_deg or xyz_mm, exactly one;
        # rpy_deg only with xyz_mm; q_deg one angle per joint of the robot;
        # target ids unique.
        (r"targets", "give target"),
        (r"targets", "not both"),
        (r"(targets\[\d+\]|target)\.(q_deg|rpy_deg)", ""),
        (r"(targets\[\d+\]|target)\.target", "appears twice"),
    ],
    "POST /sessions/{id}/jobs": [
        # Held parameters are this robot's (j1..jN), never with the
        # paper's method; rig_anchors needs a rig of four strings or more.
        (r"hold", ""),
        (r"rig_anchors", ""),
        # A job needs a session with poses: the session's state, as an
        # unknown id's 404 is the store's.
        (r"\.", "has no poses: upload some first"),
    ],
}


@schemathesis.hook
def filter_failure(ctx, failure, case, response):
    if getattr(failure, "code", None) != "ST202" or response.status_code != 422:
        return True
    # A text/csv body of POST /compensate is a targets.csv table
    # (DATA_FORMAT.md), any string to the schema: its rows are checked
    # as data, and a negative case of it is refused all the same.
    if case.operation.label == "POST /compensate" and (case.media_type or "").startswith("text/csv"):
        DROPPED[(case.operation.label, "text/csv body")] += 1
        return False
    rules = CROSS_FIELD.get(case.operation.label)
    if not rules:
        return True
    try:
        body = response.json()
    except ValueError:
        return True
    field = body.get("field") or "."
    message = body.get("message") or ""
    for field_re, words in rules:
        if re.fullmatch(field_re, field) and words in message:
            DROPPED[(case.operation.label, f"{field_re} {words!r}")] += 1
            return False
    return True
