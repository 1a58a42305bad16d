"""The numbers the paper published for its prototype (section V): what the evaluation is compared with.

:data:`PAPER` holds Table I (shape reconstruction on the validation strips, per
calibration degree n), the bounds of Fig. 9 quoted in the text, the tip-load errors of
Fig. 10, the contact-force errors of Table II and the timings, as printed in the paper.
They are data, not code: nothing here is computed.
"""

__all__ = ["PAPER"]

#: The published numbers of paper section V (Table I, Fig. 9, Fig. 10, Table II, timing).
PAPER = {
    "table_i": {
        "radius_mm": (45.75, 55.75, 65.75, 75.75, 85.75, 95.75, 150.75),
        "kappa_val_per_m": (21.86, 17.94, 15.21, 13.20, 11.66, 10.44, 6.63),
        1: {
            "kappa_recon_per_m": (21.65, 17.60, 14.99, 12.98, 11.50, 10.20, 6.74),
            "dkappa_pct": (0.94, 1.88, 1.43, 1.71, 1.39, 2.29, 1.63),
            "dp_max_pct": (3.98, 2.61, 1.67, 1.42, 1.77, 2.62, 1.21),
            "dkappa_all_pct": (1.61, 0.42),
            "dp_max_all_pct": (2.19, 0.96),
        },
        2: {
            "kappa_recon_per_m": (21.77, 17.73, 15.11, 13.07, 11.58, 10.26, 6.69),
            "dkappa_pct": (0.38, 1.13, 0.65, 0.99, 0.74, 1.80, 0.87),
            "dp_max_pct": (3.66, 2.65, 1.85, 1.24, 1.19, 2.10, 0.98),
            "dkappa_all_pct": (0.94, 0.45),
            "dp_max_all_pct": (1.95, 0.95),
        },
        3: {
            "kappa_recon_per_m": (21.69, 17.75, 15.20, 13.20, 11.71, 10.40, 6.74),
            "dkappa_pct": (0.76, 1.04, 0.08, 0.08, 0.46, 0.41, 1.69),
            "dp_max_pct": (3.01, 2.05, 1.50, 1.22, 1.19, 1.27, 0.89),
            "dkappa_all_pct": (0.65, 0.58),
            "dp_max_all_pct": (1.59, 0.72),
        },
    },
    # Fig. 9(a): upper bounds quoted in the text
    "fig9_model_max_pct": 6.0,
    "fig9_sensor_max_pct": 6.32,
    # Fig. 10: mean ± std of the tip-load error in % of 0.3 N
    "fig10_all_pct": (11.9, 14.4),
    "fig10_0_to_0p2_pct": (5.49, 4.99),
    # Table II: mean errors in % of the largest contact force, per force range
    "table_ii": {
        "ranges_n": ((0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4)),
        "none": {
            "fx": (4.13, 8.13, 17.70, 6.29, 14.90),
            "fy": (2.93, 2.51, 13.18, 42.95, 12.91),
            "fc": (4.27, 4.40, 9.04, 12.19, 7.21),
        },
        "normal": {
            "fx": (1.57, 3.02, 7.42, 9.15, 5.15),
            "fy": (3.91, 3.43, 4.29, 21.01, 6.77),
            "fc": (2.61, 1.35, 7.52, 8.17, 4.86),
        },
    },
    "reconstruction_hz": 35.0,
    "force_none_s": 0.42,
    "force_constrained_s": 1.38,
}
