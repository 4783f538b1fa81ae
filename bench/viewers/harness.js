// Renders /job.json's cameras of /scene.ply in one real viewer (?viewer=spark|playcanvas) on a black background and
// POSTs each frame's canvas as a PNG to /frame/<i>, then /done; an error goes to /error. Cameras: width, height,
// fov_y (degrees), eye, and the camera's right / up / back axes in world coordinates (a centred pinhole).
const post = (path, body) => fetch(path, { method: "POST", body });
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function spark(job, canvas) {
  const THREE = await import("three");
  const { SparkRenderer, SplatMesh } = await import("@sparkjsdev/spark");
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setClearColor(0x000000, 1);
  const scene = new THREE.Scene();
  scene.add(new SparkRenderer({ renderer }));  // Spark's defaults: the rules the spark preset models
  const mesh = new SplatMesh({ url: "/scene.ply" });
  await mesh.initialized;
  scene.add(mesh);
  const cam = new THREE.PerspectiveCamera(50, 1, 0.05, 1000);
  return async (c) => {
    renderer.setSize(c.width, c.height, false);
    cam.fov = c.fov_y;
    cam.aspect = c.width / c.height;
    cam.updateProjectionMatrix();
    cam.position.set(...c.eye);
    const m = new THREE.Matrix4().makeBasis(new THREE.Vector3(...c.right), new THREE.Vector3(...c.up),
                                            new THREE.Vector3(...c.back));
    cam.quaternion.setFromRotationMatrix(m);
    cam.updateMatrixWorld(true);
    // the sort runs in a worker and lands a frame or more later: render until it has settled
    for (let k = 0; k < job.settle_frames; ++k) {
      renderer.render(scene, cam);
      await sleep(job.settle_ms);
    }
  };
}

async function playcanvas(job, canvas) {
  const pc = await import("playcanvas");
  const app = new pc.Application(canvas, { graphicsDeviceOptions: { antialias: false, preserveDrawingBuffer: true,
                                                                    deviceTypes: ["webgl2"] } });
  app.setCanvasFillMode(pc.FILLMODE_NONE);
  app.setCanvasResolution(pc.RESOLUTION_FIXED);
  const asset = new pc.Asset("scene", "gsplat", { url: "/scene.ply" });
  app.assets.add(asset);
  await new Promise((ok, bad) => { asset.once("load", ok); asset.once("error", bad); app.assets.load(asset); });
  const splat = new pc.Entity();
  splat.addComponent("gsplat", { asset });
  app.root.addChild(splat);
  const camera = new pc.Entity();
  camera.addComponent("camera", { clearColor: new pc.Color(0, 0, 0, 1), nearClip: 0.05, farClip: 1000 });
  app.root.addChild(camera);
  app.start();
  return async (c) => {
    canvas.width = c.width;
    canvas.height = c.height;
    app.resizeCanvas(c.width, c.height);
    camera.camera.fov = c.fov_y;
    camera.setPosition(...c.eye);
    const m = new pc.Mat4().set([...c.right, 0, ...c.up, 0, ...c.back, 0, 0, 0, 0, 1]);
    camera.setRotation(new pc.Quat().setFromMat4(m));
    for (let k = 0; k < job.settle_frames; ++k) {
      app.render();
      await sleep(job.settle_ms);
    }
  };
}

const VIEWERS = { spark, playcanvas };

async function main() {
  const viewer = new URLSearchParams(location.search).get("viewer");
  const job = await (await fetch("/job.json")).json();
  const canvas = document.getElementById("c");
  const show = await VIEWERS[viewer](job, canvas);
  for (let i = 0; i < job.cameras.length; ++i) {
    await show(job.cameras[i]);
    const png = await new Promise((r) => canvas.toBlob(r, "image/png"));
    await post(`/frame/${i}`, png);
  }
  await post("/done", "");
}

main().catch((e) => post("/error", String(e && e.stack ? e.stack : e)));
