import json, sys
for f in sys.argv[1:]:
    d = json.load(open(f))
    print(f, d["effects_selected"], d["suspects"])
    print(" sensor", {p["name"]: round(p["value"], 5) for p in d["sensor_timing"]})
    m = d["metrics"]
    print(" heldout", {k: round(v["rmse_over_noise"], 2) for k, v in m["heldout_after"].items()}, "before", {k: round(v["rmse_over_noise"], 2) for k, v in m["heldout_before"].items()})
    print(" causal", {k: round(m[k]["rmse"]["ball_angle"], 5) for k in m if k.startswith("prediction_causal_") and "rmse" in m[k]})
    print(" smoothed", {k: round(m[k]["rmse"]["ball_angle"], 5) for k in m if k.startswith("prediction_") and not k.startswith("prediction_causal") and "rmse" in m[k]})
    g = d["grip"]; print(" grip", g["verdict"], g["slip_test"]["law"], g["slip_test"].get("tau_s"), {k: round(v, 3) for k, v in g["slip_test"]["train_cost"].items()})
    print(" params", [(p["name"], round(p["value"], 6), p["plausible"]) for p in d["parameters"] if p["effect"] != "frame_shape"])
