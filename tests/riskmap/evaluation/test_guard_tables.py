"""The guard's result tables: intervention totals, the ratio cell, the table written beside its rows."""

import json

from riskmap.evaluation.guard_tables import intervention_totals, markdown_table, print_table, ratio_cell


def test_totals_count_only_guarded_records():
    records = [{"guard": {"frames": 10, "interventions": 2}}, {"guard": {"frames": 30, "interventions": 2}},
               {"collided": False}]
    totals = intervention_totals(records)
    assert totals == {"frames": 40, "interventions": 4, "intervention_ratio": 0.1}
    assert ratio_cell(totals) == "0.100"


def test_no_decision_frame_has_no_ratio():
    totals = intervention_totals([{"collided": True}])
    assert totals["intervention_ratio"] is None
    assert ratio_cell(totals) == "–"


def test_the_table_is_printed_and_written_with_its_rows(tmp_path, capsys):
    rows = [{"variant": "tgat", "intervention_ratio": 0.25}]

    def markdown(rs):
        return "".join(f"| {r['variant']} | {ratio_cell(r)} |\n" for r in rs)

    print_table(rows, markdown, tmp_path / "sub" / "table")
    assert "| tgat | 0.250 |" in capsys.readouterr().out
    assert json.loads((tmp_path / "sub" / "table.json").read_text()) == rows
    assert (tmp_path / "sub" / "table.md").read_text() == "| tgat | 0.250 |\n"
    print_table(rows, markdown, None)
    assert "| tgat |" in capsys.readouterr().out


def test_markdown_table_has_header_rule_and_a_line_per_row():
    assert markdown_table(("variant", "BDI ratio"), [("tgat", "0.250"), ("alone", None)]) == (
        "| variant | BDI ratio |\n|---|---|\n| tgat | 0.250 |\n| alone | None |\n")
    assert markdown_table(("a",), []) == "| a |\n|---|\n"
