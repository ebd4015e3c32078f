/* cuda_output.cuh: the host's side of printing and checkpoints: its worker threads (cuda_parallel), and
 * the state's downloads, written while the next batch runs.
 * Part of cuda.cu, which includes it after its host-side types and the files before it (cuda.cu's
 * list). */

/* The host threads of cuda_parallel: started once, then woken for each call (the output is written
 * in rounds of a few MB, some 800 calls for a state of 1e8 disks), up to 16 with the calling thread. */
struct HostPool {
    std::mutex lock;
    std::condition_variable wake, done;
    std::vector<std::thread> threads;
    void (*task)(void *, int64_t) = nullptr;
    void *ctx = nullptr;
    int64_t tasks = 0, busy = 0, generation = 0;
    std::atomic<int64_t> next{0};
    int workers = 0; /* threads of this call, the caller among them */

    void run_tasks()
    {
        for (int64_t k; (k = next++) < tasks;) task(ctx, k);
    }
    void worker(int me)
    {
        int64_t seen = 0;
        std::unique_lock<std::mutex> g(lock);
        for (;;) {
            wake.wait(g, [&] { return generation != seen; });
            seen = generation;
            if (me >= workers - 1) continue; /* not needed this time */
            g.unlock();
            run_tasks();
            g.lock();
            if (--busy == 0) done.notify_one();
        }
    }
};
/* never destroyed: a thread that ends the program (a failed write) must not wait for itself */
static HostPool &host_pool = *new HostPool;

static void cuda_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    unsigned hw = std::thread::hardware_concurrency();
    int64_t nt = threads > 0 ? threads : hw > 1 ? (int64_t)hw : 1;
    if (nt > 16 && threads <= 0) nt = 16;
    if (nt > tasks) nt = tasks;
    if (nt <= 1) {
        for (int64_t k = 0; k < tasks; k++) task(ctx, k);
        return;
    }
    HostPool &p = host_pool;
    std::unique_lock<std::mutex> g(p.lock);
    while ((int64_t)p.threads.size() < nt - 1) {
        int me = (int)p.threads.size();
        p.threads.emplace_back([me]() { host_pool.worker(me); });
        p.threads.back().detach();
    }
    p.task = task;
    p.ctx = ctx;
    p.tasks = tasks;
    p.next = 0;
    p.workers = (int)nt;
    p.busy = nt - 1;
    p.generation++;
    g.unlock();
    p.wake.notify_all();
    p.run_tasks();
    g.lock();
    p.done.wait(g, [&] { return p.busy == 0; });
}

/* Print mode: the current state, in original order, on its way to out_host[b]. */
static void print_enqueue(Cuda *c, int b)
{
    int64_t n = c->n;
    real *d = c->out_dev;
    unpermute_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(c->st[c->cur], n, d, d + n, d + 2 * n, d + 3 * n,
                                                               c->ctl);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaMemcpyAsync(c->out_host[b], d, (size_t)n * 4 * sizeof(real), cudaMemcpyDeviceToHost,
                               c->stream));
}

/* A checkpoint's counts, beside the state that print_enqueue has put on its way to out_host[b]. */
static void counts_enqueue(Cuda *c, int b)
{
    int64_t n = c->n;
    int32_t *counts = (int32_t *)(c->out_host[b] + 4 * n);
    CUDA_CHECK(cudaMemcpyAsync(counts, c->pc, (size_t)n * 4, cudaMemcpyDeviceToHost, c->stream));
    CUDA_CHECK(cudaMemcpyAsync(counts + n, c->wc, (size_t)n * 4, cudaMemcpyDeviceToHost, c->stream));
}

/* The state in out_host[b] (its batch complete) as a Sim: x, y, vx, vy, and with checkpoints p, w. */
static Sim host_view(const Cuda *c, int b)
{
    int64_t n = c->n;
    Sim view;
    memset(&view, 0, sizeof view);
    view.x = c->out_host[b];
    view.y = view.x + n;
    view.vx = view.x + 2 * n;
    view.vy = view.x + 3 * n;
    if (c->checkpoints) {
        view.pc = (int32_t *)(view.x + 4 * n);
        view.wc = view.pc + n;
    }
    return view;
}

/* Saves the checkpoint of whole step `step` from out_host[b]. */
static void checkpoint_state(Cuda *c, Output *out, int b, int64_t step)
{
    Sim view = host_view(c, b);
    io_checkpoint(out, &view, step);
}

/* Formats the state in out_host[b]. */
static void print_state(Cuda *c, Output *out, int b, int64_t step)
{
    Sim view = host_view(c, b);
    io_write_lines(out, step, &view, c->n, 0);
}

/* The final state into sim, in original order: put in that order on the device (into the other state
 * buffer, free by now), then copied into sim's arrays a piece at a time on a thread of its own, while
 * the host threads format and write the pieces already there (io_write_final). */
#define DOWNLOAD_PIECE (1 << 18) /* disks per piece: about 10 MB */

struct Download {
    const Cuda *c;
    Sim *sim;
    const real *x, *vx; /* the state in original order on the device */
    std::mutex lock;
    std::condition_variable more;
    int64_t ready = 0; /* disks 0 .. ready-1 are in sim */
};

static void download_run(Download *d)
{
    int64_t n = d->c->n;
    for (int64_t a = 0; a < n; a += DOWNLOAD_PIECE) {
        int64_t m = n - a < DOWNLOAD_PIECE ? n - a : DOWNLOAD_PIECE;
        size_t nd = (size_t)m * sizeof(real), ni = (size_t)m * sizeof(int32_t);
        CUDA_CHECK(cudaMemcpy(d->sim->x + a, d->x + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->y + a, d->x + n + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->vx + a, d->vx + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->vy + a, d->vx + n + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->pc + a, d->c->pc + a, ni, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->wc + a, d->c->wc + a, ni, cudaMemcpyDeviceToHost));
        std::lock_guard<std::mutex> g(d->lock);
        d->ready = a + m;
        d->more.notify_all();
    }
}

static void download_await(void *ctx, int64_t lines)
{
    Download *d = (Download *)ctx;
    std::unique_lock<std::mutex> g(d->lock);
    d->more.wait(g, [&] { return d->ready >= lines; });
}

static void state_download_and_write(Cuda *c, Sim *sim, Output *out)
{
    int64_t n = c->n;
    DevState *spare = &c->st[1 - c->cur];
    real *x = (real *)spare->d, *vx = x + 2 * n; /* its 4 n reals as x, y, vx, vy */
    unpermute_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(c->st[c->cur], n, x, x + n, vx, vx + n, c->ctl);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaStreamSynchronize(c->stream));
    Download d;
    d.c = c;
    d.sim = sim;
    d.x = x;
    d.vx = vx;
    std::thread copier(download_run, &d);
    io_write_final(out, sim, download_await, &d);
    copier.join();
}
