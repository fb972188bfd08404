"""PyTorch CPU reference of one DeepReach training iteration (the same work as fastrack-trainer's):
SIREN forward, dV/dinput with torch.autograd.grad(create_graph=True) as DeepReach does, the HJI-VI
residual loss of the Dubins car, backward, Adam. Prints iterations/s as JSON. ENCODING (default circle) is
how the heading enters the first layer, as in the trainer: `circle` (cos and sin of its phase) or `wrap`.
Usage: python3 torch_step.py WIDTH DEPTH POINTS ITERATIONS [ENCODING]"""
import json, sys, time
import torch

width, depth, points, iterations = (int(a) for a in sys.argv[1:5])
circle = (sys.argv[5] if len(sys.argv) > 5 else "circle") == "circle"
torch.manual_seed(0)
n_in = 6  # tau, x_r, y_r, theta, v, beta (diagonal mode)
n_features = n_in + 1 if circle else n_in
layers = [torch.nn.Linear(n_features if i == 0 else width, width) for i in range(depth)] + [torch.nn.Linear(width, 1)]
params = [p for l in layers for p in l.parameters()]
opt = torch.optim.Adam(params, lr=1e-4)

def features(x):
    if not circle:
        return x
    phase = torch.pi * x[:, 3:4]
    return torch.cat([x[:, :3], x[:, 4:], torch.cos(phase), torch.sin(phase)], 1)

def net(x):
    x = features(x)
    for l in layers[:-1]:
        x = torch.sin(30.0 * l(x))
    return layers[-1](x)

def step():
    x = torch.rand(points, n_in) * 2 - 1
    x.requires_grad_(True)
    y = net(x)
    g = torch.autograd.grad(y.sum(), x, create_graph=True)[0]
    tau = (x[:, :1] + 1) * 1.5
    r = x[:, 1:5] * torch.tensor([3.0, 3.0, 3.14159, 1.5]) + torch.tensor([0, 0, 0, 1.5])
    beta = x[:, 5:6] * 0.375 + 0.875
    l = torch.sqrt(r[:, :1] ** 2 + r[:, 1:2] ** 2)
    v = l + tau * y
    p = g[:, 1:5] * tau
    h = p[:, :1] * r[:, 3:4] * torch.sin(r[:, 2:3]) + p[:, 1:2] * r[:, 3:4] * torch.cos(r[:, 2:3]) \
        + beta * (p[:, :1].abs() + p[:, 1:2].abs()) - 5 * p[:, 2:3].abs() - p[:, 3:4].abs()
    dv_dtau = y + tau * g[:, :1]
    loss = torch.minimum(v - l, dv_dtau - h).abs().mean()
    opt.zero_grad()
    loss.backward()
    opt.step()

step()
start = time.perf_counter()
for _ in range(iterations):
    step()
elapsed = time.perf_counter() - start
print(json.dumps({"iterations_per_s": iterations / elapsed, "threads": torch.get_num_threads(), "torch": torch.__version__}))
