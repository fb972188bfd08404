"""The project's own deployment rules, which the generic validators do not know. Run by validate.sh with the
deploy tools' Python (PyYAML comes with yamllint). Each rule prints the file and what breaks it; the exit
status is the number of broken rules.

  python deploy/policy.py compose FILE                published ports bind to loopback
  python deploy/policy.py network RENDERED...         every pod template is selected by a NetworkPolicy that
                                                      limits both ingress and egress
  python deploy/policy.py same-image SERVER JOBS...   the Jobs run the image of the overlay's server
"""

import sys

import yaml

LOOPBACK = ("127.0.0.1:", "[::1]:", "localhost:")


def documents(path):
    with open(path, encoding="utf-8") as f:
        return [d for d in yaml.safe_load_all(f) if d]


def compose_ports_on_loopback(path):
    """Every published port of every service names a loopback host address."""
    problems = []
    for name, service in (documents(path)[0].get("services") or {}).items():
        for port in service.get("ports") or []:
            host_ip = port.get("host_ip") if isinstance(port, dict) else None
            text = str(port)
            if not (host_ip in ("127.0.0.1", "::1") or text.startswith(LOOPBACK)):
                problems.append(f"{path}: services.{name}.ports {text!r} publishes on every interface; "
                                f"bind it to loopback ('127.0.0.1:{text}')")
    return problems


def pod_templates(docs):
    """(kind/name, pod labels) of every workload's pod template."""
    for d in docs:
        if d.get("kind") in ("Deployment", "StatefulSet", "DaemonSet", "Job"):
            labels = d["spec"]["template"].get("metadata", {}).get("labels", {})
            yield f"{d['kind']}/{d['metadata']['name']}", labels


def selects(selector, labels):
    """True if a label selector (matchLabels, matchExpressions with In / NotIn / Exists) selects labels."""
    if any(labels.get(k) != v for k, v in (selector.get("matchLabels") or {}).items()):
        return False
    for e in selector.get("matchExpressions") or []:
        key, op, values = e["key"], e["operator"], e.get("values", [])
        if (op == "In" and labels.get(key) not in values) or (op == "NotIn" and labels.get(key) in values) \
                or (op == "Exists" and key not in labels) or (op == "DoesNotExist" and key in labels):
            return False
    return True


def pods_under_network_policy(paths):
    """Each pod template is selected by a NetworkPolicy of its own file listing Ingress and Egress."""
    problems = []
    for path in paths:
        docs = documents(path)
        policies = [d for d in docs if d.get("kind") == "NetworkPolicy"]
        for workload, labels in pod_templates(docs):
            types = set()
            for p in policies:
                if selects(p["spec"].get("podSelector") or {}, labels):
                    types |= set(p["spec"].get("policyTypes") or ["Ingress"])
            missing = {"Ingress", "Egress"} - types
            if missing:
                problems.append(f"{path}: {workload}'s pods are not limited by a NetworkPolicy in "
                                f"{' or '.join(sorted(missing))}")
    return problems


def jobs_run_the_servers_image(server_path, job_paths):
    """Every container of every Job runs the image of the Deployment rendered in server_path."""
    images = {c["image"] for d in documents(server_path) if d.get("kind") == "Deployment"
              for c in d["spec"]["template"]["spec"]["containers"]}
    if len(images) != 1:
        return [f"{server_path}: expected one server image, found {sorted(images)}"]
    (image,) = images
    problems = []
    for path in job_paths:
        for d in documents(path):
            if d.get("kind") == "Job":
                for c in d["spec"]["template"]["spec"]["containers"]:
                    if c["image"] != image:
                        problems.append(f"{path}: Job/{d['metadata']['name']} runs {c['image']}, "
                                        f"the server {image} ({server_path})")
    return problems


def main(argv):
    rules = {
        "compose": lambda args: compose_ports_on_loopback(args[0]),
        "network": pods_under_network_policy,
        "same-image": lambda args: jobs_run_the_servers_image(args[0], args[1:]),
    }
    if len(argv) < 2 or argv[0] not in rules:
        print(__doc__, file=sys.stderr)
        return 2
    problems = rules[argv[0]](argv[1:])
    for p in problems:
        print(p)
    return min(len(problems), 100)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
