// The one classic-script bundle the viewer loads (a module script cannot load from file://).
// Built by ../build.sh from the unmodified three.js files beside this one.
import * as THREE from "three";
import { OrbitControls } from "./addons/controls/OrbitControls.js";
import { GLTFLoader } from "./addons/loaders/GLTFLoader.js";

window.SURFGEN_THREE = { THREE, OrbitControls, GLTFLoader };
