"""Certification-evidence reports: electronic inclinometer (MSC.363(92) / ISO 19697) and heading device
(MSC.116(73) / ISO 22090-2), as JSON (schema in ``schema/evidence.schema.json``) and PDF.

Library use::

    from imutool.report.inclinometer import inclinometer_evidence
    from imutool.report.pdf import render_pdf, write_json
    ev, plots = inclinometer_evidence(dut_rec, ref_rec, dut_path=..., ref_path=...)
    write_json(ev, "evidence.json"); render_pdf(ev, plots, "evidence.pdf")

or the whole command, from paths to the PDF and JSON with its exit status (:mod:`imutool.report.route`)::

    from imutool.report.route import run_inclinometer_report
    res = run_inclinometer_report("dut.csv", "table.csv", "evidence.pdf")   # res.exit_status, res.summary
"""
